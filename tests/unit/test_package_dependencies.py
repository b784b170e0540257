"""Every package declares in its package.xml what its code imports, by rosdep key, so that
`rosdep install` on a full ROS 2 install brings everything in; and every key that rosdep's own
database lacks is defined in rosdep/robot_sim.yaml, installing the package pinned here."""
import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
# Python packages (ament_python): those at the top level are linked into ros_ws/src.
PACKAGES = sorted({p.parent.resolve() for p in [*ROOT.glob('*/package.xml'),
                                                *ROOT.glob('ros_ws/src/*/package.xml')]
                   if (p.parent / 'setup.py').is_file()})

# Third-party Python modules and their rosdep keys. The keys without "-pip" and
# python3-pybullet-pip are in rosdep's default database (ros/rosdistro rosdep/python.yaml);
# the others are defined in rosdep/robot_sim.yaml.
PYTHON_KEYS = {
    'numpy': 'python3-numpy', 'cv2': 'python3-opencv', 'yaml': 'python3-yaml',
    'tqdm': 'python3-tqdm', 'pybullet': 'python3-pybullet-pip',
    'pybullet_utils': 'python3-pybullet-pip', 'rosbags': 'python3-rosbags-pip',
    'mcap': 'python3-mcap-pip', 'mcap_ros2': 'python3-mcap-ros2-support-pip',
    'zstandard': 'python3-zstandard-pip', 'ruckig': 'python3-ruckig-pip',
    'ray': 'python3-ray-pip', 'foxglove': 'python3-foxglove-sdk-pip',
    'websockets': 'python3-websockets', 'cryptography': 'python3-cryptography',
    're2': 'python3-google-re2-pip', 'optuna': 'python3-optuna-pip',
    'SALib': 'python3-salib-pip', 'scipy': 'python3-scipy', 'matplotlib': 'python3-matplotlib',
    'pybullet_data': 'python3-pybullet-pip',
    # (pinocchio, its Python bindings' base eigenpy and its collision library coal are ROS
    # packages of the distribution: their keys are their names.)
    'pinocchio': 'pinocchio', 'eigenpy': 'eigenpy', 'coal': 'coal',
}
# Modules that come with rclpy or the interface packages, declared by their ROS package name.
ROS_MODULES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'ament_index_python',
               'launch', 'launch_ros', 'rosgraph_msgs'}


def _depends(package: Path) -> set:
    root = ET.parse(package / 'package.xml').getroot()
    return {e.text.strip() for e in root if e.tag in ('depend', 'exec_depend') and e.text}


def _imports(package: Path) -> set:
    found = set()
    for path in (package / package.name).rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {a.name.split('.')[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split('.')[0])
    return found - set(sys.stdlib_module_names) - {'__future__', package.name}


def _workspace_packages() -> set:
    return {p.name for p in PACKAGES} | {
        p.parent.name for p in ROOT.glob('ros_ws/src/**/package.xml')}


@pytest.mark.parametrize('package', PACKAGES, ids=[p.name for p in PACKAGES])
def test_package_declares_what_it_imports(package):
    depends = _depends(package)
    ours = _workspace_packages()
    missing = []
    for module in sorted(_imports(package)):
        if module in PYTHON_KEYS:
            key = PYTHON_KEYS[module]
        elif module in ours or module in ROS_MODULES or module.endswith(('_msgs', '_srvs')):
            key = module
        else:
            missing.append(f'{module} (no rosdep key known: add it to PYTHON_KEYS)')
            continue
        if key not in depends:
            missing.append(f'{module} -> <exec_depend>{key}</exec_depend>')
    assert not missing, f'{package.name}/package.xml lacks: {missing}'


def test_project_rosdep_keys_install_the_pinned_packages():
    rules = yaml.safe_load((ROOT / 'rosdep' / 'robot_sim.yaml').read_text())
    pinned = {m.group(1).lower() for m in re.finditer(
        r'^([A-Za-z0-9_.-]+)==', (ROOT / 'requirements' / 'py3.11.txt').read_text(), re.M)}
    declared = set().union(*(_depends(p) for p in PACKAGES))
    for key in {k for k in declared if k.endswith('-pip')} - {'python3-pybullet-pip'}:
        assert key in rules, f'{key} is declared but not defined in rosdep/robot_sim.yaml'
    for key, rule in rules.items():
        for platform in ('debian', 'ubuntu'):
            names = rule[platform]['pip']['packages']
            assert names and all(n.lower() in pinned for n in names), (key, names)
