"""ROS's rules for the names a world gives and the names they make (rmw's rules for a fully
qualified name, and its length limits), without ROS."""
from __future__ import annotations

import re

# rmw's limits (rmw/validate_full_topic_name.h, validate_namespace.h): a DDS topic name holds
# 256 characters, less the prefixes and suffixes rmw adds ("rq/", "Request").
MAX_NAME_LENGTH = 247
MAX_NAMESPACE_LENGTH = MAX_NAME_LENGTH - 2
# Ours: a name a world gives (a robot, a camera, a controller, a class): it goes into other
# names, file names (a trial's log files) and the lines a user reads.
MAX_TOKEN_LENGTH = 64
# A token of a ROS name: a letter or an underscore first, then letters, digits, underscores.
TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')


# A fully qualified name ROS takes (its length aside).
_FULL = re.compile(r'/|(/[A-Za-z_][A-Za-z0-9_]*)+')


def name_problem(name: str) -> str:
    """Why ``name`` (fully qualified) is not a name ROS takes, or ''."""
    if len(name) <= MAX_NAME_LENGTH and _FULL.fullmatch(name):
        return ''
    if not name.startswith('/'):
        return 'is not absolute'
    if len(name) > MAX_NAME_LENGTH:
        return f'is {len(name)} characters long (ROS takes at most {MAX_NAME_LENGTH})'
    if name == '/':
        return ''
    for token in name[1:].split('/'):
        if not token:
            return 'has an empty part (// or a trailing /)'
        if not TOKEN.fullmatch(token):
            return (f'has the part {token[:40]!r}: a part is a letter or _, then letters, '
                    'digits or _')
    return ''


def token_problem(value: str) -> str:
    """Why ``value`` is not a name a world may give (a ROS name's token, at most
    MAX_TOKEN_LENGTH characters), or ''."""
    if len(value) > MAX_TOKEN_LENGTH:
        return f'is {len(value)} characters long (at most {MAX_TOKEN_LENGTH})'
    if not re.fullmatch(r'[A-Za-z][A-Za-z0-9_]*', value):
        return 'must be a ROS name ([A-Za-z][A-Za-z0-9_]*)'
    return ''


def relative_problem(value: str) -> str:
    """Why ``value`` is not a relative ROS name of parts (``cell/picker``), or ''."""
    if len(value) > MAX_NAMESPACE_LENGTH:
        return f'is {len(value)} characters long (at most {MAX_NAMESPACE_LENGTH})'
    problem = name_problem('/' + value)
    return problem.replace('is not absolute', 'must be relative') if value else 'is empty'
