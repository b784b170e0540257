"""The floors of the house: the ROS-free packages import no ROS, and the vision and the
coordinator do not need the simulator."""
import ast

import pytest

from helpers import ROOT

ROS_FREE = ('controllers', 'world_description')
# (ament_index_python, a plain lookup of installed files, is not among them: the floor finds
# package:// resources with it when it is there.)
ROS_MODULES = ('rclpy', 'builtin_interfaces', 'rcl_interfaces', 'rosgraph_msgs', 'launch',
               'launch_ros')


def _imports(package: str):
    """(file, imported top-level module) for every import in a package's modules."""
    for path in sorted((ROOT / package / package).rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                yield path.relative_to(ROOT), name.split('.')[0]


def _is_ros(module: str) -> bool:
    return (module in ROS_MODULES or module.endswith('_msgs') or module.endswith('_srvs')
            or module.endswith('_interfaces'))


@pytest.mark.parametrize('package', ROS_FREE)
def test_the_ros_free_floor_imports_no_ros(package):
    found = [f'{path}: {module}' for path, module in _imports(package) if _is_ros(module)]
    assert found == []


@pytest.mark.parametrize('package', ('perception', 'coordinator'))
def test_the_vision_and_the_coordinator_do_not_import_the_simulator(package):
    found = [f'{path}: {module}' for path, module in _imports(package)
             if module == 'sim_bridge']
    assert found == []


def test_the_check_sees_an_import_of_ros():
    assert _is_ros('sensor_msgs') and _is_ros('std_srvs') and _is_ros('rclpy')
    assert any(module == 'rclpy' for _, module in _imports('ros_common'))
