"""Parameters declared from a table (ros_common.params): descriptions, ranges by the default's
type, choices refused in one clear line, and a parameter without a default read as None."""
import pytest
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ros_common.params import Param, declare_params

TABLE = (
    Param('rate', 10.0, 'A rate [Hz]', 0.1, 100.0),
    Param('count', 3, 'A count', 1, 10),
    Param('mode', 'fast', 'A mode', choices=('fast', 'slow')),
    Param('names', Parameter.Type.STRING_ARRAY, 'Names, unset by default'),
    Param('speed', 1.0, 'Settable while running', read_only=False),
)


def _node(context, **overrides):
    return Node('table_test', context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in overrides.items()])


def test_the_table_is_declared_described_and_read_back(context):
    node = _node(context, count=5)
    try:
        values = declare_params(node, TABLE)
        assert values == {'rate': 10.0, 'count': 5, 'mode': 'fast', 'names': None,
                          'speed': 1.0}
        assert node.describe_parameter('count').integer_range[0].to_value == 10
        assert node.describe_parameter('rate').floating_point_range[0].from_value == 0.1
        assert 'one of: fast, slow' in node.describe_parameter('mode').description
        assert node.describe_parameter('rate').read_only
        assert not node.describe_parameter('speed').read_only
    finally:
        node.destroy_node()


@pytest.mark.parametrize('override, why', [({'rate': 1000.0}, 'range'), ({'count': 0}, 'range'),
                                           ({'mode': 'sometimes'},
                                            'mode must be one of fast, slow')])
def test_a_value_out_of_range_or_choices_is_refused(context, override, why):
    node = _node(context, **override)
    try:
        with pytest.raises(InvalidParameterValueException, match=why):
            declare_params(node, TABLE)
    finally:
        node.destroy_node()


def test_a_range_needs_a_numeric_default():
    with pytest.raises(TypeError, match='numeric default'):
        Param('x', 'text', 'A string with a range', 0.0, 1.0).descriptor()
