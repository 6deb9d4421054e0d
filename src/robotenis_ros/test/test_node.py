"""Parameters declared from one table."""
import rclpy
from rclpy.parameter import Parameter

from robotenis_ros.node import declare_parameters

TABLE = {'rate': (1000.0, 'Hz'), 'name': ('x', 'a name'), 'gains': ([1.0, 2.0], 'two gains')}


def test_the_table_is_declared_with_its_defaults_overrides_and_descriptions():
    rclpy.init()
    try:
        overrides = [Parameter('rate', value=250.0)]
        node = rclpy.create_node('table_test', parameter_overrides=overrides)
        values = declare_parameters(node, TABLE, name='y')
        assert values == {'rate': 250.0, 'name': 'y', 'gains': [1.0, 2.0]}
        assert node.describe_parameter('gains').description == 'two gains'
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
