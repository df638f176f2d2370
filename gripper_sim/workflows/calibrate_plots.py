"""Figures of a calibration: measured against fitted force-deformation curves.

``plot_png`` draws with matplotlib (no display needed); ``plot_html`` writes a
self-contained interactive plotly page (plotly.js embedded, opens offline). Both show
the measured points, the fitted curve, the curve of the starting (preset) values, the
bruise onset when one was calibrated, and the force residuals below.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from plotly.subplots import make_subplots

from gripper_sim.workflows.calibrate_bruise import BruiseCalibration
from gripper_sim.configuration import SCHEMA
from gripper_sim.workflows.html_page import write_figure_page
from gripper_sim.workflows.calibrate_fit import FitResult, FittedKey


#: relative standard error above which a fitted value is called undetermined (as the
#: calibrate command prints it)
UNDETERMINED = 10.0


def _fitted_value(key: FittedKey) -> str:
    """'flesh.youngs_modulus = 9.971e+05 Pa +/- 1.5 %': the value with its SI unit (the
    configuration's) and its relative standard error."""
    unit = SCHEMA[key.key].unit if key.key in SCHEMA else ''
    unit = f' {unit}' if unit not in ('', '-') else ''
    spread = (f'+/- {key.relative_error:.1%}' if key.relative_error < UNDETERMINED
              else '(undetermined)')
    return f'{key.key.removeprefix("fruit.")} = {key.value:.4g}{unit} {spread}'


def _title(result: FitResult, name: str) -> str:
    fitted = ', '.join(_fitted_value(k) for k in result.keys)
    return (f'{name}: {fitted}; RMS error {result.rms_error:.3g} N '
            f'({result.relative_rms_error:.1%} of peak)')


@dataclass(frozen=True)
class _Curves:
    """What both figures draw, deformations in mm: measured (d, force), fitted - measured
    at each measured point, and the fitted and starting curves from first contact on."""

    measured_d: np.ndarray
    measured_force: np.ndarray
    residual: np.ndarray
    fitted_d: np.ndarray
    fitted_force: np.ndarray
    start_d: np.ndarray
    start_force: np.ndarray


def _curves(result: FitResult) -> _Curves:
    measured, fitted, start = result.measured, result.fitted, result.start
    keep_f, keep_s = fitted.deformation >= 0, start.deformation >= 0
    return _Curves(measured.deformation * 1e3, measured.force,
                   fitted.force_at(measured.deformation) - measured.force,
                   fitted.deformation[keep_f] * 1e3, fitted.force[keep_f],
                   start.deformation[keep_s] * 1e3, start.force[keep_s])


def plot_png(result: FitResult, path: str | Path, name: str,
             bruise: BruiseCalibration | None = None) -> None:
    """Write the PNG figure to ``path``."""
    c = _curves(result)
    figure = Figure(figsize=(8, 6.5), dpi=110, layout='constrained')
    FigureCanvasAgg(figure)
    top, bottom = figure.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    top.plot(c.measured_d, c.measured_force, 'o', color='black', markersize=4, label='measured')
    top.plot(c.fitted_d, c.fitted_force, '-', color='tab:blue', linewidth=2, label='fitted model')
    top.plot(c.start_d, c.start_force, '--', color='tab:gray', linewidth=1,
             label='starting values (preset)')
    if bruise is not None:
        top.axvline(bruise.observed_deformation * 1e3, color='tab:red', linestyle=':',
                    label=f'bruise onset ({bruise.bruise_pressure / 1e3:.0f} kPa)')
    top.set_ylabel('force (N)')
    top.set_ylim(0, 1.15 * max(float(c.measured_force.max()), float(c.fitted_force.max())))
    top.legend(loc='upper left')
    top.grid(alpha=0.3)
    top.set_title(_title(result, name), fontsize=9)
    bottom.axhline(0, color='gray', linewidth=0.8)
    bottom.plot(c.measured_d, c.residual, 'o-', color='tab:blue', markersize=3)
    bottom.set_xlabel('deformation (plate travel since first contact, mm)')
    bottom.set_ylabel('fitted - measured (N)')
    bottom.grid(alpha=0.3)
    figure.savefig(path)


def plot_html(result: FitResult, path: str | Path, name: str,
              bruise: BruiseCalibration | None = None) -> None:
    """Write the self-contained HTML figure (plotly.js included) to ``path``."""
    c = _curves(result)
    figure = make_subplots(rows=2, cols=1, shared_xaxes=True, row_heights=[0.75, 0.25],
                           vertical_spacing=0.06)
    figure.add_trace(go.Scatter(x=c.measured_d, y=c.measured_force, mode='markers',
                                name='measured', marker=dict(color='black', size=6)),
                     row=1, col=1)
    figure.add_trace(go.Scatter(x=c.fitted_d, y=c.fitted_force, mode='lines', name='fitted model',
                                line=dict(color='#1f77b4', width=3)), row=1, col=1)
    figure.add_trace(go.Scatter(x=c.start_d, y=c.start_force, mode='lines',
                                name='starting values (preset)',
                                line=dict(color='gray', dash='dash')), row=1, col=1)
    figure.add_trace(go.Scatter(x=c.measured_d, y=c.residual, mode='lines+markers',
                                name='fitted - measured', line=dict(color='#1f77b4')),
                     row=2, col=1)
    if bruise is not None:
        figure.add_vline(x=bruise.observed_deformation * 1e3, line_dash='dot',
                         line_color='red', row=1, col=1,
                         annotation_text=f'bruise onset ({bruise.bruise_pressure / 1e3:.0f} kPa)')
    figure.update_yaxes(title_text='force (N)', row=1, col=1)
    figure.update_yaxes(title_text='fitted - measured (N)', row=2, col=1)
    figure.update_xaxes(title_text='deformation (plate travel since first contact, mm)',
                        row=2, col=1)
    figure.update_layout(title=_title(result, name), template='plotly_white')
    write_figure_page(path, f'Calibration of {name}', figure)
