"""The package's import contracts (``.importlinter``): layers that import only downward
(every top-level module in one), no import cycle between the modules of a package, no ROS
in the physics.

``lint-imports`` (import-linter, from this venv) reads every import of the package, those
inside functions too. The contracts are also checked against copies of the package with
one bad import planted, so that a contract which no longer catches anything fails here.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sys.executable).parent / 'lint-imports'


def lint_imports(root: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` on the ``gripper_sim`` under ``root`` with the contracts of ROOT."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(root), env.get('PYTHONPATH', '')])
    return subprocess.run([str(LINT_IMPORTS), str(ROOT / '.importlinter'), '--no-cache',
                           '--no-logo'], cwd=root, env=env, capture_output=True, text=True)


def test_the_package_keeps_its_import_contracts():
    run = lint_imports(ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert ' kept, 0 broken.' in run.stdout


PLANTS = {
    'upward': ({'core/planted.py': 'import gripper_sim.cli\n'},
               ['Layers import only downward BROKEN',
                'gripper_sim.core is not allowed to import gripper_sim.cli',
                'gripper_sim.core.planted -> gripper_sim.cli']),
    'ros in the physics': ({'core3d/planted.py': 'def connect():\n    import rclpy\n'},
                           ['The physics and its workflows know nothing about ROS BROKEN',
                            'gripper_sim.core3d.planted -> rclpy']),
    'module without a layer': ({'params.py': 'SPEED = 1.0\n'},
                               ['Layers import only downward BROKEN',
                                'The following modules are not listed as layers:',
                                '- gripper_sim.params']),
    'cycle': ({'core/planted_a.py': 'from gripper_sim.core import planted_b\n',
               'core/planted_b.py': 'def back():\n    from gripper_sim.core import planted_a\n'},
              ['No import cycles between the modules of a package BROKEN',
               'No cycles are allowed in gripper_sim.core.']),
}


@pytest.mark.parametrize('plant', sorted(PLANTS))
def test_a_planted_bad_import_breaks_a_contract(tmp_path, plant):
    files, expected = PLANTS[plant]
    shutil.copytree(ROOT / 'gripper_sim', tmp_path / 'gripper_sim',
                    ignore=shutil.ignore_patterns('__pycache__'))
    for name, text in files.items():
        (tmp_path / 'gripper_sim' / name).write_text(text)
    run = lint_imports(tmp_path)
    assert run.returncode != 0, run.stdout
    for line in expected:
        assert line in run.stdout, run.stdout
