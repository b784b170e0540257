"""The project's Fast DDS profiles (``share/ros_common/config/fastdds*.xml``) and how a
launcher hands one to the processes it starts.

Fast DDS reads the file named by ``FASTRTPS_DEFAULT_PROFILES_FILE`` (``FASTDDS_...`` from Fast
DDS 3) once per process, when the first context is created. Both profiles give the
shared-memory transport a segment that holds several 640x480 rgb8 frames (the default 512 KiB
holds none). ``fastdds.xml``, the default, holds UDP to the loopback interface: no socket of a
node listens on another interface. ``fastdds_network.xml`` opens UDP to every interface; it is
chosen when the user asks for discovery beyond this machine the standard way
(``ROS_AUTOMATIC_DISCOVERY_RANGE`` SUBNET or SYSTEM_DEFAULT, or ``ROS_STATIC_PEERS``). A
profile the user chose always wins: nothing here replaces one that is set, and a middleware
other than Fast DDS gets none.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import IO, Dict, Iterable, Mapping, Optional, Tuple

PACKAGE = 'ros_common'
PROFILE_FILE = 'config/fastdds.xml'
NETWORK_PROFILE_FILE = 'config/fastdds_network.xml'
# ROS_AUTOMATIC_DISCOVERY_RANGE values that reach beyond this machine.
OPEN_RANGES = ('SUBNET', 'SYSTEM_DEFAULT')
# Fast DDS 2 (Jazzy) reads the first, Fast DDS 3 the second.
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
# The shared-memory segment the profile asks for, in bytes (a test reads it back from the file
# and from the segment Fast DDS creates).
SEGMENT_SIZE = 8 * 1024 * 1024


def wants_network(env: Mapping[str, str]) -> bool:
    """Whether the user asked for discovery beyond this machine."""
    return (env.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '').upper() in OPEN_RANGES
            or bool(env.get('ROS_STATIC_PEERS', '').strip()))


def profile_path(network: bool = False) -> Optional[Path]:
    """The installed profile (loopback only, or open to the network), or None when
    ros_common's share directory cannot be found."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )
    except ImportError:
        return None
    try:
        path = (Path(get_package_share_directory(PACKAGE))
                / (NETWORK_PROFILE_FILE if network else PROFILE_FILE))
    except PackageNotFoundError:
        return None
    return path if path.is_file() else None


def uses_fastdds(env: Mapping[str, str]) -> bool:
    return env.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp').startswith('rmw_fastrtps')


def profile_environment(env: Optional[Mapping[str, str]] = None) -> Dict[str, str]:
    """The variables to add to ``env`` (default: this process's) so that a child process runs
    with the project's profile (the network one if ``env`` asks for discovery beyond this
    machine): none if a profile is already chosen, the middleware is not Fast DDS, or the
    profile is not installed."""
    env = os.environ if env is None else env
    if any(env.get(name) for name in PROFILE_VARIABLES) or not uses_fastdds(env):
        return {}
    path = profile_path(wants_network(env))
    if path is None:
        return {}
    return {name: str(path) for name in PROFILE_VARIABLES}


def with_profile(env: Mapping[str, str]) -> Dict[str, str]:
    """``env`` plus :func:`profile_environment`'s variables."""
    return {**env, **profile_environment(env)}


def hold_free_domain(candidates: Iterable[int], lock_dir: Path
                     ) -> Optional[Tuple[int, IO[str]]]:
    """The first DDS domain of ``candidates`` that no other process on this host holds, and
    the open lock file that now holds it (an advisory lock on a file per domain in
    ``lock_dir``; closing the file, or the holder's end, frees the domain); None if all are
    held. Trials on one machine (run_trials, Ray workers) and test sessions take their domains
    so."""
    lock_dir.mkdir(mode=0o777, parents=True, exist_ok=True)
    for domain in candidates:
        lock = open(lock_dir / f'{domain}.lock', 'a')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return domain, lock
    return None
