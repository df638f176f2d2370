"""Where the CPU time of a barrier-contact run goes inside the compiled kernels: the cases
of ``profile_barrier.py`` (``fin_ray``, ``ring``) sampled by Linux ``perf``. Prints
figures; asserts nothing.

``profile_barrier.py`` times each kernel call from Python; inside a kernel, and inside
the compiled Newton solve that holds most of them, it sees nothing. Here ``perf record``
samples the whole process, and this script names numba's machine code for it: after a
warm-up run it writes ``/tmp/perf-PID.map`` (perf's map of JIT code, read at report
time) with the entry point of every compiled overload of every kernel in a loaded
``gripper_sim`` module, each taken to run to the next entry point. Inlined kernels are
counted in their caller: with the compiled solve (the default) the Newton iteration is
one symbol, ``barrier_newton.solve``; ``--interpreted`` runs the Newton loop in Python
(``fast_solver.COMPILED_BARRIER_SOLVE = False``), so the energies, the barrier, the
linear solve and the filters are separate symbols (their Python glue slower than on the
compiled route).

``--inside`` compiles every kernel afresh in the sampled run (numba's cache in a
temporary folder, ~3 min of CPU before the warm-up ends) and names every function of
each kernel's machine code as well (``inner_functions``: a kernel loaded from the cache
keeps no module to list them from): the kernels the compiled solve calls that LLVM did
not inline (the block LDL^T solve, CG's matrix product, the energies, the barrier's
terms) become their own symbols, on the compiled route. The fresh compile leaves numba's
compiler objects on the heap, so the Python collector's share of the samples is larger
than in a normal run (compare the JIT symbols among themselves).

Usage::

    python bench/perf_kernels.py [fin_ray|ring] [--interpreted] [--inside] [--runs N]
        [--top K]

It runs itself under ``perf record`` (4 kHz; started with sampling off, switched on
through perf's control FIFO once the warm-up run is done, so that imports and numba's
cache loading stay out) and prints the top symbols of ``perf report`` by their own
samples (the Python interpreter's functions among them), then the samples by shared
object.
"""
from __future__ import annotations

import argparse
import os
import pkgutil
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))
sys.path.insert(0, str(ROOT / 'test'))

#: the environment variable that marks the run perf samples: the directory of perf's
#: control FIFOs and of the child's process id
CHILD = 'GRIPPER_SIM_PERF_CHILD'


def kernel_entries() -> list[tuple[int, str]]:
    """(address, 'module.kernel') of every compiled overload of the numba kernels bound in
    a loaded ``gripper_sim`` module, sorted by address."""
    import gripper_sim
    from numba.core.registry import CPUDispatcher
    entries, seen = [], set()
    for info in pkgutil.walk_packages(gripper_sim.__path__, 'gripper_sim.'):
        module = sys.modules.get(info.name)
        if module is None:
            continue
        for attribute, value in vars(module).items():
            if not isinstance(value, CPUDispatcher) or id(value) in seen:
                continue
            seen.add(id(value))
            for result in value.overloads.values():
                address = result.library.get_pointer_to_function(result.fndesc.llvm_func_name)
                if address:
                    entries.append((address, f"{value.py_func.__module__.split('.')[-1]}."
                                             f'{value.py_func.__name__}'))
                entries.extend(inner_functions(result.library))
    return sorted(dict(entries).items())


def _short_name(mangled: str) -> str:
    """'module.function' of a numba function's mangled symbol (an Itanium-style nested
    name: length-prefixed parts, the last two kept; the symbol itself if it is not one)."""
    if not mangled.startswith('_ZN'):
        return mangled
    parts, text = [], mangled[3:]
    while True:
        match = re.match(r'(\d+)', text)
        if not match:
            break
        size, skip = int(match.group(1)), len(match.group(1))
        parts.append(text[skip:skip + size])
        text = text[skip + size:]
    return '.'.join(parts[-2:]) if parts else mangled


def inner_functions(library) -> list[tuple[int, str]]:
    """(address, name) of every function defined in a compiled kernel's code (the kernels
    it calls and LLVM did not inline): known only for code compiled in this process
    (``--inside``: a library loaded from numba's cache keeps no module to list)."""
    module = getattr(library, '_final_module', None)
    if module is None:
        return []
    found = []
    for function in module.functions:
        if function.is_declaration:
            continue
        address = library.get_pointer_to_function(function.name)
        if address:
            found.append((address, _short_name(function.name)))
    return found


def write_perf_map(entries: list[tuple[int, str]]) -> Path:
    """Write perf's JIT map of this process: each entry runs to the next (at most 1 MB)."""
    path = Path(f'/tmp/perf-{os.getpid()}.map')
    with path.open('w') as out:
        for k, (address, name) in enumerate(entries):
            end = entries[k + 1][0] if k + 1 < len(entries) else address + 0x10000
            out.write(f'{address:x} {min(end - address, 0x100000):x} {name}\n')
    return path


def child(case: str, runs: int, folder: Path) -> None:
    """The sampled process: a warm-up run, the map, sampling switched on (perf's control
    FIFO in ``folder``), then ``runs`` runs."""
    from profile_barrier import run
    run(case)
    write_perf_map(kernel_entries())
    (folder / 'pid').write_text(str(os.getpid()))
    with open(folder / 'ctl', 'w') as control, open(folder / 'ack') as ack:
        control.write('enable\n')
        control.flush()
        ack.readline()
    for _ in range(runs):
        run(case)


def report(data: Path, top: int) -> None:
    """Print perf report's top symbols and the shared objects of ``data``."""
    for sort, count in (('sym', top), ('dso', 8)):
        text = subprocess.run(
            ['perf', 'report', '-i', str(data), '--no-children', '--sort', sort, '-g',
             'none', '--stdio'], capture_output=True, text=True, check=True).stdout
        lines = [line for line in text.splitlines() if line.strip() and not
                 line.startswith('#')]
        print(f'by {"symbol" if sort == "sym" else "shared object"}:')
        print('\n'.join(lines[:count]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('case', nargs='?', default='fin_ray', choices=('fin_ray', 'ring'))
    parser.add_argument('--interpreted', action='store_true',
                        help='the Newton loop in Python: each kernel its own symbol')
    parser.add_argument('--runs', type=int, default=6, help='runs sampled (default 6)')
    parser.add_argument('--top', type=int, default=30, help='symbols listed (default 30)')
    parser.add_argument('--inside', action='store_true',
                        help="compile every kernel afresh in this run (numba's cache in a "
                             'temporary folder, several minutes) so that the functions '
                             'inside a kernel are named too')
    args = parser.parse_args(argv)
    if args.interpreted:
        from gripper_sim.core import fast_solver
        fast_solver.COMPILED_BARRIER_SOLVE = False
    if os.environ.get(CHILD):
        child(args.case, args.runs, Path(os.environ[CHILD]))
        return 0
    if shutil.which('perf') is None:
        print('perf_kernels: needs Linux perf (the linux-perf package)', file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        data = folder / 'perf.data'
        for fifo in ('ctl', 'ack'):
            os.mkfifo(folder / fifo)
        command = ['perf', 'record', '-q', '-F', '4000', '-g', '-D', '-1',
                   f'--control=fifo:{folder / "ctl"},{folder / "ack"}', '-o', str(data),
                   sys.executable, __file__, *(argv if argv is not None else sys.argv[1:])]
        env = dict(os.environ, **{CHILD: tmp})
        if args.inside:
            env['NUMBA_CACHE_DIR'] = str(folder / 'numba-cache')
        subprocess.run(command, env=env, check=True)
        print(f'{args.case}{" (interpreted Newton loop)" if args.interpreted else ""}: '
              f'{args.runs} runs after a warm-up, load average {os.getloadavg()[0]:.2f}; '
              'share of the samples')
        try:
            report(data, args.top)
        finally:
            Path(f"/tmp/perf-{(folder / 'pid').read_text()}.map").unlink(missing_ok=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
