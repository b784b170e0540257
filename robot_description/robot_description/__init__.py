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


def with_frame_prefix(urdf: str, prefix: str) -> str:
    """The URDF text with every link renamed ``<prefix><name>`` (the links themselves and the
    joints' parent and child links), so that a robot with a frame prefix is drawn from its own
    frames. Joint names stay: joint_states name the joints without a prefix."""
    if not prefix:
        return urdf
    import xml.etree.ElementTree as ET
    root = ET.fromstring(urdf)
    if root.tag != 'robot':
        raise ValueError(f'not a URDF: the root element is <{root.tag}>, not <robot>')
    for link in root.iter('link'):
        if 'name' in link.attrib:
            link.set('name', prefix + link.get('name', ''))
    for joint in root.iter('joint'):
        for end in ('parent', 'child'):
            for element in joint.findall(end):
                element.set('link', prefix + element.get('link', ''))
    for reference in root.iter('gazebo'):
        if 'reference' in reference.attrib:
            reference.set('reference', prefix + reference.get('reference', ''))
    return ET.tostring(root, encoding='unicode')
