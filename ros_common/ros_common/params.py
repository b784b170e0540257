"""The project's nodes' parameters: declared once from a table, with their descriptions and
ranges (checked by rclpy at declaration), and read back as one mapping."""
from dataclasses import dataclass
from typing import Any, Dict, Optional, Sequence, Tuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.node import Node

from ros_common.web_access import WebAccess


@dataclass(frozen=True)
class Param:
    """One parameter of a node.

    ``default``: its value (whose type is the parameter's), or a ``Parameter.Type`` for one
    declared without a default (read back as None while unset). ``low``/``high``: an inclusive
    range, integer or floating-point as the default. ``choices``: the only values a string
    may take. ``read_only``: set at start-up only (most are)."""
    name: str
    default: Any
    description: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Tuple[str, ...] = ()
    read_only: bool = True

    def descriptor(self) -> ParameterDescriptor:
        text = self.description + (f' (one of: {", ".join(self.choices)})'
                                   if self.choices else '')
        d = ParameterDescriptor(description=text, read_only=self.read_only)
        if self.low is not None and self.high is not None:
            if isinstance(self.default, bool) or not isinstance(self.default, (int, float)):
                raise TypeError(f'{self.name}: a range needs a numeric default')
            if isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(self.low),
                                                to_value=int(self.high), step=1)]
            else:
                d.floating_point_range = [FloatingPointRange(
                    from_value=float(self.low), to_value=float(self.high), step=0.0)]
        return d


def declare_params(node: Node, table: Sequence[Param]) -> Dict[str, Any]:
    """Declare every parameter of ``table`` on ``node`` and return their values by name (None
    for one declared without a default and not given). rclpy refuses a value out of its range
    at declaration; a string outside its choices is refused here the same way
    (InvalidParameterValueException: ``run_node`` logs it as one line, "bad parameter")."""
    values: Dict[str, Any] = {}
    for param in table:
        node.declare_parameter(param.name, param.default, param.descriptor())
        try:
            value = node.get_parameter(param.name).value
        except ParameterUninitializedException:
            value = None
        if param.choices and value not in param.choices:
            raise InvalidParameterValueException(
                param.name, value, f'{param.name} must be one of {", ".join(param.choices)}')
        values[param.name] = value
    return values


def declare_web_access(node: Node, host: str, origins: Sequence[str], origins_meaning: str,
                       clients_name: str, clients_what: str) -> Tuple[WebAccess, int]:
    """The parameters of a node's web server who may reach it (``allowed_hosts``,
    ``allowed_origins``, the cap on clients ``clients_name``, 16 by default), declared; its
    rules and cap. Raises WebAccessError for a bad rule."""
    node.declare_parameter('allowed_hosts', [''], ParameterDescriptor(
        description='Host names the server may be reached by besides loopback and the served '
                    'address (a request naming another host is refused: a page of another '
                    'site that made its name resolve here)', read_only=True))
    node.declare_parameter('allowed_origins', list(origins) or [''], ParameterDescriptor(
        description='Regular expressions of the origins (scheme://host:port) of the web pages '
                    f'that may connect besides its own; {origins_meaning}', read_only=True))
    node.declare_parameter(clients_name, 16, ParameterDescriptor(
        description=f'{clients_what} connected at once; past that one is refused (503)',
        read_only=True, integer_range=[IntegerRange(from_value=1, to_value=1024, step=1)]))
    access = WebAccess(host, node.get_parameter('allowed_hosts').value,
                       node.get_parameter('allowed_origins').value)
    return access, int(node.get_parameter(clients_name).value)
