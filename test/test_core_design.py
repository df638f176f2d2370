"""Design contracts: the core has no ROS in it; objects keep their private state to
themselves; the README documents every config key."""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

from gripper_sim.config_doc import markdown_table
from gripper_sim.configuration import SCHEMA

ROOT = Path(__file__).resolve().parents[1]


def test_core_imports_without_rclpy():
    code = ('import sys; import gripper_sim.core.simulation, gripper_sim.workflows.grasp, '
            'gripper_sim.cli.offline; print("rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout.strip()
    assert out == 'False'


def test_readme_documents_every_config_key():
    readme = (ROOT / 'README.md').read_text()
    missing = [key for key in SCHEMA if f'`{key}`' not in readme]
    assert not missing, f'README lacks {missing}: run python scripts/update_readme_config.py'


def test_readme_config_table_is_the_generated_one():
    readme = (ROOT / 'README.md').read_text()
    assert markdown_table() in readme, 'README table is stale: run scripts/update_readme_config.py'


def test_config_table_lists_the_presets_values_beside_the_built_in_default():
    row = next(line for line in markdown_table().splitlines()
               if line.startswith('| `fruit.pressure.turgor`'))
    cells = [cell.strip() for cell in row.split('|')]
    assert cells[2] == '0'
    assert '30000 (apple, orange)' in cells[3] and '130000 (peach)' in cells[3]
    unchanged = next(line for line in markdown_table().splitlines()
                     if line.startswith('| `sim.max_halvings`'))
    assert unchanged.split('|')[3].strip() == ''


#: (module, reach) pairs of ``private_reaches`` that stay, and why
PRIVATE_REACHES_ALLOWED = {
    # numba's struct proxies (cgutils) give their LLVM value only as ``_getvalue()``
    ('core/kernels.py', 'view._getvalue'),
    # a copy of ``self`` made in its own method: the same class's state
    ('convert/messages.py', 'copy._node_bruised'),
    # rclpy's Node has no public getter of the parameter overrides it was started with; the
    # node's error message shows the value given (read with a default: never raises)
    ('ros/params.py', 'self._node._parameter_overrides'),
    # rclpy moves a goal to CANCELING only on a client's request; a preempted goal is
    # canceled by the server, the move made as rclpy's own server makes it
    ('ros/goal_end.py', 'goal_handle._update_state'),
}


def private_reaches(source: str) -> list[str]:
    """Every ``<object>._name`` in ``source`` (attribute reads, writes, calls and
    ``getattr``/``setattr``/``hasattr`` with a constant name) whose object is not ``self``,
    ``cls``, ``super()`` or a class the module defines itself: one object reaching into
    another's private state. ``__dunder__`` names are public."""
    tree = ast.parse(source)
    own_classes = {node.name for node in ast.walk(tree) if isinstance(node, ast.ClassDef)}
    mine = {'self', 'cls'} | own_classes
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            target, name = node.value, node.attr
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ('getattr', 'setattr', 'hasattr') and len(node.args) >= 2
              and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str)):
            target, name = node.args[0], node.args[1].value
        else:
            continue
        if not name.startswith('_') or name.startswith('__'):
            continue
        if isinstance(target, ast.Name) and target.id in mine:
            continue
        if (isinstance(target, ast.Call) and isinstance(target.func, ast.Name)
                and target.func.id == 'super'):
            continue
        found.append(f'{ast.unparse(target)}.{name}')
    return found


def test_no_module_reaches_into_another_objects_private_state():
    package = ROOT / 'gripper_sim'
    reaches = {(path.relative_to(package).as_posix(), reach)
               for path in sorted(package.rglob('*.py'))
               for reach in private_reaches(path.read_text())}
    assert not reaches - PRIVATE_REACHES_ALLOWED, (
        'private members read or written from outside their object (make them public, '
        'read-only, or give the owner a method): '
        f'{sorted(reaches - PRIVATE_REACHES_ALLOWED)}')
    assert not PRIVATE_REACHES_ALLOWED - reaches, 'stale allowances: drop them'


#: (module, imported name) pairs of ``private_imports`` that stay, and why: compiled
#: (numba) helpers inlined into another module's kernels, whose names their own modules
#: keep private
PRIVATE_IMPORTS_ALLOWED = {
    ('core/advance_kernels.py', 'gripper_sim.core.kernels._packed1'),
    ('core3d/fingers_pad.py', 'gripper_sim.core.pad._f0'),
    ('core3d/fingers_pad.py', 'gripper_sim.core.pad._f1'),
    ('core3d/fingers_pad.py', 'gripper_sim.core.pad._df1'),
}


def private_imports(source: str) -> list[str]:
    """Every ``from gripper_sim.<module> import _name`` in ``source``: a module using
    another's private helper."""
    return [f'{node.module}.{alias.name}' for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.ImportFrom) and (node.module or '').startswith('gripper_sim')
            for alias in node.names
            if alias.name.startswith('_') and not alias.name.startswith('__')]


def test_no_module_imports_another_modules_private_helpers():
    package = ROOT / 'gripper_sim'
    imports = {(path.relative_to(package).as_posix(), name)
               for path in sorted(package.rglob('*.py'))
               for name in private_imports(path.read_text())}
    assert not imports - PRIVATE_IMPORTS_ALLOWED, (
        f'private helpers imported from another module (make them public): '
        f'{sorted(imports - PRIVATE_IMPORTS_ALLOWED)}')
    assert not PRIVATE_IMPORTS_ALLOWED - imports, 'stale allowances: drop them'


@pytest.mark.parametrize('source, expected', [
    ('sim._grip = grip', ['sim._grip']),
    ('x = self.sim._faces_template', ['self.sim._faces_template']),
    ('path._face_arrays()', ['path._face_arrays']),
    ("getattr(sim, '_time')", ['sim._time']),
    ('self._grip = grip; cls._make(); super()._substep(dt); x.__class__', []),
    ('class A:\n    pass\nA._restore(1)', []),
])
def test_the_private_reach_scan_sees_what_it_should(source, expected):
    assert private_reaches(source) == expected


def test_the_private_import_scan_sees_what_it_should():
    source = ('from gripper_sim.core.pad import PadLayer, _f0\n'
              'from numpy import _private\nfrom gripper_sim import __version__')
    assert private_imports(source) == ['gripper_sim.core.pad._f0']
