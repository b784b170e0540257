"""Where a resource named in a world file is: ``package://``, ``file://`` or a plain path."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from world_description.errors import ResourceError

__all__ = ['ResourceError', 'package_share', 'resolve_resource']


PYBULLET_DATA = 'pybullet_data://'


def resolve_resource(uri: str, base_dir: Optional[Path] = None) -> Path:
    """Resolve ``package://pkg/rel``, ``pybullet_data://rel`` (a model PyBullet bundles, as
    ``franka_panda/panda.urdf``), ``file://`` or a path (relative to ``base_dir``, the world
    file's directory, when given)."""
    if uri.startswith(PYBULLET_DATA):
        import pybullet_data
        return Path(pybullet_data.getDataPath()) / uri[len(PYBULLET_DATA):]
    if uri.startswith('package://'):
        package, _, rel = uri[len('package://'):].partition('/')
        return package_share(package) / rel
    if uri.startswith('file://'):
        uri = uri[len('file://'):]
    path = Path(uri)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    return path


def package_share(package: str) -> Path:
    """A package's share directory, from the ament index (the workspace sourced), else a
    package of this source tree (a directory beside this package's, with its package.xml):
    the floor finds the robots' files without importing their package."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            return Path(get_package_share_directory(package))
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            pass
    except ImportError:
        pass
    source = Path(__file__).resolve().parent.parent.parent / package
    if (source / 'package.xml').is_file():
        return source
    raise ResourceError(f'package "{package}" not found in the ament index '
                        '(is the workspace sourced?)')
