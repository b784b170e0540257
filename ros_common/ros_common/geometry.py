"""geometry_msgs to and from the plain tuples and arrays of the project's cores."""
from __future__ import annotations

from typing import Any, Tuple

from controllers.transforms import yaw_from_quaternion


def quaternion_tuple(q: Any) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a geometry_msgs Quaternion."""
    return (q.x, q.y, q.z, q.w)


def yaw_of(q: Any) -> float:
    """The yaw of a geometry_msgs Quaternion."""
    return yaw_from_quaternion(quaternion_tuple(q))
