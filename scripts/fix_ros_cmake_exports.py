"""Re-point the build machine's Python paths in the ROS wheels' CMake exports.

The ``ros-jazzy-*`` wheels ship CMake export files
(``share/<pkg>/cmake/*__rosidl_generator_pyExport.cmake``) that name the Python of
the machine that built them (``/opt/python/cp311-cp311/...``). Configuring a
package that depends on them (our interface package) then fails on include
directories that do not exist. This rewrites those paths to this venv's own
Python include directory and ``numpy.get_include()``.

Run it with the venv's interpreter: ``$VENV/bin/python fix_ros_cmake_exports.py``.
Idempotent: a second run finds nothing to change.
"""
from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_PYTHON = '/opt/python/cp311-cp311'
REPLACEMENTS = (
    # Longest first: the numpy include lies under the build Python's prefix.
    (f'{BUILD_PYTHON}/lib/python3.11/site-packages/numpy/_core/include', numpy.get_include()),
    (f'{BUILD_PYTHON}/lib/python3.11/site-packages/numpy/core/include', numpy.get_include()),
    (f'{BUILD_PYTHON}/include/python3.11', sysconfig.get_paths()['include']),
)


def main() -> int:
    prefix = Path(sys.prefix)
    include = Path(sysconfig.get_paths()['include'])
    if not (include / 'Python.h').is_file():
        print(f'error: no Python.h in {include}: install the Python development headers',
              file=sys.stderr)
        return 1
    changed = 0
    for path in sorted((prefix / 'share').rglob('*.cmake')):
        text = path.read_text(encoding='utf-8', errors='surrogateescape')
        if BUILD_PYTHON not in text:
            continue
        new = text
        for old, replacement in REPLACEMENTS:
            new = new.replace(old, replacement)
        if new != text:
            path.write_text(new, encoding='utf-8', errors='surrogateescape')
            changed += 1
        if BUILD_PYTHON in new:
            print(f'warning: {path} still names {BUILD_PYTHON}', file=sys.stderr)
    print(f'fix_ros_cmake_exports: re-pointed {changed} CMake export file(s) in {prefix}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
