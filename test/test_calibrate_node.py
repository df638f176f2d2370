"""A calibrated preset file as the node's ``fruit`` parameter, like a built-in fruit."""
import json

import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter

from gripper_sim.cli.main import main
from gripper_sim.errors import ConfigError
from gripper_sim.ros.params import SimParameters

pytestmark = pytest.mark.ros

ROWS = ''.join(f'{d:.1f},{1.6 * d ** 1.2:.3f}\n' for d in (0.5, 1, 1.5, 2, 2.5, 3, 3.5, 4))


def test_node_fruit_parameter_takes_a_preset_file(tmp_path, capsys):
    data = tmp_path / 'curve.csv'
    data.write_text('deformation_mm,force_N\n' + ROWS)
    preset = tmp_path / 'orchard_apple.yaml'
    assert main(['calibrate', '--data', str(data), '--fit', 'pressure.turgor', '--set',
                 'fruit.nodes=24', '-o', str(preset), '--no-plots', '--json']) == 0
    turgor = json.loads(capsys.readouterr().out)['fitted']['fruit.pressure.turgor']['value']
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node('calibrated_fruit_params', context=context,
                    parameter_overrides=[Parameter('fruit', value=str(preset))])
        params = SimParameters(node)
        assert params.config['fruit.name'] == 'orchard_apple'
        assert params.config['fruit.pressure.turgor'] == pytest.approx(turgor)
        assert node.get_parameter('physics.fruit.nodes').value == 24
        node.destroy_node()
        bad = Node('missing_fruit_params', context=context,
                   parameter_overrides=[Parameter('fruit', value=str(tmp_path / 'no.yaml'))])
        with pytest.raises(ConfigError, match="fruit preset file '.*no.yaml' not found"):
            SimParameters(bad)
        bad.destroy_node()
    finally:
        rclpy.shutdown(context=context)
