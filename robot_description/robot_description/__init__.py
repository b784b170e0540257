"""Locate the project's robot descriptions (installed share directory or source tree)."""
from __future__ import annotations

from pathlib import Path

_SOURCE_URDF_DIR = Path(__file__).resolve().parent.parent / 'urdf'


def share_directory() -> Path:
    """The package's share directory, through the ament index when it is available."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            return Path(get_package_share_directory('robot_description'))
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            pass
    except ImportError:
        pass
    return _SOURCE_URDF_DIR.parent


def urdf_path(robot: str) -> Path:
    """Path of ``urdf/<robot>.urdf``; raises FileNotFoundError naming what exists."""
    path = share_directory() / 'urdf' / f'{robot}.urdf'
    if not path.is_file():
        path = _SOURCE_URDF_DIR / f'{robot}.urdf'
    if not path.is_file():
        known = sorted(p.stem for p in _SOURCE_URDF_DIR.glob('*.urdf'))
        raise FileNotFoundError(f'no URDF for robot "{robot}"; known: {known}')
    return path
