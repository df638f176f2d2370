"""Print the pins of every distribution pip installed in this venv (for requirements.txt).

Run with the venv's interpreter. Unlike ``pip freeze`` it leaves out the ROS wheels'
inner ``*.egg-info`` records (``rclpy==7.1.5``, ``std_msgs==5.3.6``, ...), which name
no package on any index, and the editable project itself.
"""
from __future__ import annotations

import sys
from importlib import metadata

SKIP = {'pip', 'gripper-sim', 'gripper_sim'}


def main() -> int:
    pins = {}
    for dist in metadata.distributions():
        name = dist.metadata['Name']
        if not name or name.lower() in SKIP:
            continue
        if (dist.read_text('INSTALLER') or '').strip() != 'pip':
            continue
        pins[name.lower()] = f'{name}=={dist.version}'
    print('\n'.join(pins[key] for key in sorted(pins)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
