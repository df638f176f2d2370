"""Design contracts: the core has no ROS in it; the README documents every config key."""
import subprocess
import sys
from pathlib import Path

from gripper_sim.configuration import SCHEMA

ROOT = Path(__file__).resolve().parents[1]


def test_core_imports_without_rclpy():
    code = ('import sys; import gripper_sim.core.simulation, gripper_sim.core.grasp, '
            'gripper_sim.cli.offline; print("rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout.strip()
    assert out == 'False'


def test_readme_documents_every_config_key():
    readme = (ROOT / 'README.md').read_text()
    missing = [key for key in SCHEMA if f'`{key}`' not in readme]
    assert not missing, f'README lacks {missing}: run python scripts/update_readme_config.py'
