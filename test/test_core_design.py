"""Design contracts: the core has no ROS in it; the README documents every config key."""
import subprocess
import sys
from pathlib import Path

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
