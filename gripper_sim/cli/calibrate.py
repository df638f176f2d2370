"""``gripper-sim calibrate``: fit a fruit model to a measured plate compression test and
write it as a fruit preset (``gripper_sim.workflows.calibrate_*``)."""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from gripper_sim.cli.offline import add_config_arguments
from gripper_sim.configuration import PRESET_SUFFIXES, parse_override
from gripper_sim.workflows.calibrate_data import (FORCE_UNITS, LENGTH_UNITS, SPEED_UNITS,
                                                  CalibrationError, parse_quantity,
                                                  read_curve)

#: relative standard error from which a value is shown as undetermined
UNDETERMINED = 10.0


def _quantity(units: dict[str, float], bare_unit: str | None, what: str):
    """argparse type: a number with a unit of ``units`` (a bare number is in ``bare_unit``;
    None: a unit is required)."""
    def parse(text: str) -> float:
        if bare_unit is not None:
            try:
                float(text)
                text = f'{text}{bare_unit}'
            except ValueError:
                pass
        try:
            return parse_quantity(text, units, what)
        except CalibrationError as err:
            raise argparse.ArgumentTypeError(str(err)) from None
    return parse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'calibrate', help='fit a fruit model to a measured plate compression test',
        description='Read a force-deformation curve (CSV) of a plate compression test, '
                    'simulate the same test (squeeze), fit the chosen keys by bounded least '
                    'squares and write a fruit preset (YAML) with a PNG and an HTML plot of '
                    'measured against fitted curves.')
    parser.add_argument('--data', required=True, metavar='CURVE.csv',
                        help='CSV: header deformation_mm,force_N (or _m); optional comment '
                             "line '# plate_speed: 20 mm/min'")
    add_config_arguments(parser)
    parser.add_argument('--model', choices=('shell', 'solid'),
                        help='fruit model to calibrate (default: the preset\'s)')
    parser.add_argument('--fit', metavar='KEY,KEY',
                        help='keys to fit, each with an effect in the set-up (default: '
                             'flesh.youngs_modulus,pressure.turgor for a shell, '
                             'flesh.youngs_modulus for a solid)')
    parser.add_argument('--speed', type=_quantity(SPEED_UNITS, 'm/s', '--speed'),
                        metavar='SPEED', help='plate speed: m/s, or with a unit (20mm/min); '
                        'default: the file\'s plate_speed, else 0.005 m/s')
    parser.add_argument('--deformation-unit', choices=tuple(LENGTH_UNITS),
                        help='unit of the deformation column when the header gives none')
    parser.add_argument('--force-unit', choices=tuple(FORCE_UNITS),
                        help='unit of the force column when the header gives none')
    onset = parser.add_mutually_exclusive_group()
    onset.add_argument('--bruise-force', type=_quantity(FORCE_UNITS, 'N', '--bruise-force'),
                       metavar='N', help='force at which bruising was observed: calibrate '
                       'fruit.bruise_pressure to it')
    onset.add_argument('--bruise-deformation', metavar='LENGTH',
                       type=_quantity(LENGTH_UNITS, None, '--bruise-deformation'),
                       help='deformation at which bruising was observed, with its unit '
                            '(6.5mm)')
    parser.add_argument('-o', '--output', required=True, metavar='MYFRUIT.yaml',
                        help='fruit preset to write; the plots go beside it (.png, .html)')
    parser.add_argument('--name', help='fruit name in the preset (default: the file name)')
    parser.add_argument('--force', action='store_true', dest='overwrite',
                        help='overwrite existing output files')
    parser.add_argument('--no-plots', action='store_true', help='write the preset only')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.set_defaults(handler=run_calibrate)


def _outputs(args) -> list[Path]:
    preset = Path(args.output)
    if not preset.name.endswith(PRESET_SUFFIXES):
        raise CalibrationError(f"-o {args.output}: the preset file must end in .yaml")
    paths = [preset] if args.no_plots else [preset, preset.with_suffix('.png'),
                                            preset.with_suffix('.html')]
    for path in paths:
        if path.exists() and not args.overwrite:
            raise CalibrationError(f"'{path}' exists (use --force to overwrite it)")
        if not path.parent.is_dir():
            raise CalibrationError(f"cannot write '{path}': no directory '{path.parent}'")
    refused = _unwritable(preset.parent)
    if refused:
        raise CalibrationError(f"cannot write '{preset}': {refused}")
    return paths


def _unwritable(directory: Path) -> str | None:
    """Why no file can be created in ``directory`` (None if one can): tried with a
    temporary file, before a fit that may take minutes."""
    try:
        with tempfile.NamedTemporaryFile(dir=directory, prefix='.gripper-sim-calibrate-'):
            return None
    except OSError as err:
        return err.strerror or str(err)


def _overrides(args) -> dict:
    overrides = dict(parse_override(text) for text in args.overrides)
    if args.model is not None:
        if overrides.get('fruit.model', args.model) != args.model:
            raise CalibrationError(f"--model {args.model} contradicts --set fruit.model="
                                   f"{overrides['fruit.model']}")
        overrides['fruit.model'] = args.model
    return overrides


def run_calibrate(args) -> int:
    # imported here, as the other verbs import the core: every gripper-sim command builds
    # this parser, and scipy.optimize, matplotlib and plotly take seconds to import
    from gripper_sim.workflows.calibrate_bruise import calibrate_bruise
    from gripper_sim.workflows.calibrate_fit import fit
    from gripper_sim.workflows.calibrate_model import (CompressionTest, check_fit_keys,
                                                       fit_keys)
    from gripper_sim.workflows.calibrate_plots import plot_html, plot_png
    from gripper_sim.workflows.calibrate_preset import preset_text, write_preset
    # the inputs first: an existing output is not the error to hide a data error behind
    curve = read_curve(args.data, args.deformation_unit, args.force_unit, args.speed)
    test = CompressionTest(curve, fruit=args.fruit, overrides=_overrides(args),
                           config_file=args.config)
    keys = fit_keys(args.fit, test.model)
    check_fit_keys(keys, test.base)
    paths = _outputs(args)
    name = args.name or paths[0].stem
    text = not args.json
    if text:
        print(f'calibrating {", ".join(k.removeprefix("fruit.") for k in keys)} of the '
              f'{test.model} model ({test.dimension}D) on {curve.path}: {len(curve.force)} '
              f'points to {curve.max_deformation * 1e3:.4g} mm at '
              f'{test.speed * 1e3:.4g} mm/s; {test.base["sim.dt"]:.3g} s steps', flush=True)
    cpu = time.process_time()
    result = fit(test, keys)
    bruise = None
    if args.bruise_force is not None or args.bruise_deformation is not None:
        bruise = calibrate_bruise(test, result.config, result.fitted, args.bruise_force,
                                  args.bruise_deformation)
    cpu = time.process_time() - cpu
    write_preset(paths[0], preset_text(test, result, name, bruise), test.dimension)
    if not args.no_plots:
        plot_png(result, paths[1], name, bruise)
        plot_html(result, paths[2], name, bruise)
    if args.json:
        summary = dict(fitted={k.key: dict(value=k.value, std_error=k.std_error,
                                           start=k.start) for k in result.keys},
                       rms_error=result.rms_error, max_error=result.max_error,
                       rms_error_over_peak_force=result.relative_rms_error,
                       warnings=list(result.warnings), simulations=result.evaluations,
                       cpu_time=cpu, outputs=[str(p) for p in paths])
        if bruise is not None:
            summary['bruise'] = dict(bruise_pressure=bruise.bruise_pressure,
                                     observed_deformation=bruise.observed_deformation,
                                     simulated_deformation=bruise.simulated_deformation)
        json.dump(summary, sys.stdout)
        sys.stdout.write('\n')
        return 0
    print(f'  {result.evaluations} simulations, {cpu:.1f} s CPU')
    for k in result.keys:
        spread = (f'+/- {k.relative_error:.1%}' if k.relative_error < UNDETERMINED
                  else '(undetermined)')
        print(f'  {k.key:28s} {k.value:11.4g}  {spread:>12s}   (start {k.start:.4g})')
    print(f'  RMS force error {result.rms_error:.3g} N ({result.relative_rms_error:.1%} of '
          f'the largest force), largest {result.max_error:.3g} N')
    for warning in result.warnings:
        print(f'  warning: {warning}')
    if bruise is not None:
        onset = ('never' if bruise.simulated_deformation is None
                 else f'at {bruise.simulated_deformation * 1e3:.3g} mm')
        print(f'  bruise pressure {bruise.bruise_pressure / 1e3:.4g} kPa: observed onset '
              f'{bruise.observed_deformation * 1e3:.3g} mm ({bruise.observed_force:.3g} N), '
              f'simulated onset {onset} (steps of {bruise.step_travel * 1e3:.2g} mm)')
    print(f"  wrote {', '.join(str(p) for p in paths)}")
    return 0
