"""Message definitions for bags: the Jazzy typestore of rosbags, plus installed .msg files."""
from __future__ import annotations

import importlib
import re
from pathlib import Path
from typing import Any, List, Optional, Tuple

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

_MSGTYPE = re.compile(r'^([A-Za-z][A-Za-z0-9_]*)/msg/([A-Z][A-Za-z0-9]*)$')


class TypeResolutionError(LookupError):
    """A message type whose definition cannot be found."""


def message_class(msgtype: str) -> type:
    """The generated Python class of ``pkg/msg/Name`` (what ros2cli's get_message does)."""
    match = _MSGTYPE.match(msgtype)
    if not match:
        raise TypeResolutionError(f'"{msgtype}" is not a message type name (pkg/msg/Name)')
    try:
        module = importlib.import_module(f'{match.group(1)}.msg')
        found: type = getattr(module, match.group(2))
        return found
    except (ImportError, AttributeError) as exc:
        raise TypeResolutionError(f'cannot import {msgtype}: {exc}') from None


class TypeResolver:
    """Gives the definition and RIHS01 hash of a type, for a bag's connection records.

    Types of the Jazzy distribution come with rosbags; others (the project's own interfaces) are
    read from ``share/<pkg>/msg/<Name>.msg`` of the installed package, with their dependencies.
    """

    def __init__(self, typestore: Optional[Typestore] = None) -> None:
        self.typestore = typestore or get_typestore(Stores.ROS2_JAZZY)

    def definition(self, msgtype: str) -> Tuple[str, str]:
        """(msgdef, rihs01) of a message type; raises TypeResolutionError."""
        self._ensure(msgtype, depth=0)
        msgdef, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
        return msgdef, self.typestore.hash_rihs01(msgtype)

    def _ensure(self, msgtype: str, depth: int) -> None:
        if msgtype in self.typestore.fielddefs:
            return
        if depth > 32:
            raise TypeResolutionError(f'{msgtype}: nesting too deep')
        path = _installed_msg_file(msgtype)
        types = get_types_from_msg(path.read_text(), msgtype)
        self.typestore.register(types)
        for _, fields in types.values():
            for _, (kind, detail) in fields:
                for name in _referenced_types(kind, detail):
                    self._ensure(name, depth + 1)


def _referenced_types(kind: Any, detail: Any) -> List[str]:
    # rosbags field descriptions: (NAME, 'pkg/msg/T') or (SEQUENCE/ARRAY, ((NAME, 'pkg/msg/T'), n))
    names = []
    if isinstance(detail, str) and '/msg/' in detail:
        names.append(detail)
    elif isinstance(detail, tuple) and detail and isinstance(detail[0], tuple):
        inner = detail[0]
        if len(inner) == 2 and isinstance(inner[1], str) and '/msg/' in inner[1]:
            names.append(inner[1])
    return names


def _installed_msg_file(msgtype: str) -> Path:
    match = _MSGTYPE.match(msgtype)
    if not match:
        raise TypeResolutionError(f'"{msgtype}" is not a message type name (pkg/msg/Name)')
    package, name = match.groups()
    try:
        from ament_index_python.packages import get_package_share_directory
        share = Path(get_package_share_directory(package))
    except (ImportError, LookupError, OSError) as exc:
        raise TypeResolutionError(f'{msgtype}: package "{package}" not found ({exc})') from None
    path = share / 'msg' / f'{name}.msg'
    if not path.is_file():
        raise TypeResolutionError(f'{msgtype}: {path} does not exist')
    return path


def register_bag_definition(typestore: Typestore, msgtype: str, msgdef: str) -> None:
    """Register a type from a bag's stored (concatenated ros2msg) definition."""
    if msgtype not in typestore.fielddefs:
        typestore.register(get_types_from_msg(msgdef, msgtype))
