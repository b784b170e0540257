"""Parameter descriptors shared by the project's nodes."""
from typing import Sequence, Tuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from ros_common.web_access import WebAccess


def float_range(description: str, lo: float, hi: float,
                read_only: bool = True) -> ParameterDescriptor:
    """A described floating-point parameter that rclpy range-checks at declaration."""
    return ParameterDescriptor(description=description, read_only=read_only,
                               floating_point_range=[FloatingPointRange(
                                   from_value=lo, to_value=hi, step=0.0)])


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
