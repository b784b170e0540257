"""What the two storages share: how a connection's schema and serialization are named in
rosbag2's files."""
from __future__ import annotations

from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinitionFormat


def schema_encoding(connection: Connection) -> str:
    return 'ros2msg' if connection.msgdef.format == MessageDefinitionFormat.MSG else 'ros2idl'


def serialization_format(connection: Connection) -> str:
    ext = connection.ext
    return ext.serialization_format if isinstance(ext, ConnectionExtRosbag2) else 'cdr'
