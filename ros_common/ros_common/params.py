"""Parameter descriptors shared by the project's nodes."""
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor


def float_range(description: str, lo: float, hi: float,
                read_only: bool = True) -> ParameterDescriptor:
    """A described floating-point parameter that rclpy range-checks at declaration."""
    return ParameterDescriptor(description=description, read_only=read_only,
                               floating_point_range=[FloatingPointRange(
                                   from_value=lo, to_value=hi, step=0.0)])
