"""ament_python packaging of gripper_sim (colcon) and its pip install (the Makefile's venv)."""
from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'gripper_sim'


def config_files():
    """(share dir, [files]) pairs keeping config/'s folder layout under share/gripper_sim."""
    pairs = {}
    patterns = ('config/**/*.yaml', 'config/*.xml')
    for path in sorted(p for pattern in patterns for p in glob(pattern, recursive=True)):
        target = os.path.join('share', package_name, os.path.dirname(path))
        pairs.setdefault(target, []).append(path)
    return sorted(pairs.items())


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        *config_files(),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='gripper_sim maintainers',
    maintainer_email='gripper-sim@example.com',
    description='Simulates a parallel-jaw gripper grasping a deformable fruit.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'gripper-sim = gripper_sim.cli.main:main',
            'sim_node = gripper_sim.ros.node:main',
            'controller = gripper_sim.ros.controller:main',
        ],
    },
)
