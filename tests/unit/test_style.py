"""Style and types: ruff (ruff.toml's rules, ament's 99 columns among them) on every Python file
of the project, and mypy (mypy.ini)."""
import ast
import configparser
import fnmatch
import subprocess
import sys

from helpers import ROOT


def test_ruff_finds_nothing():
    out = subprocess.run([sys.executable, '-m', 'ruff', 'check', '--no-cache',
                          '--output-format', 'concise', '.'], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr


# Every package of the project (mypy.ini: strict on the ROS-free floor).
PACKAGES = tuple(sorted({p.parent.name for p in [*ROOT.glob('*/package.xml'),
                                                *ROOT.glob('ros_ws/src/*/package.xml')]
                        if (p.parent / 'setup.py').is_file()}))


def test_mypy_finds_nothing():
    packages = [arg for name in PACKAGES for arg in ('-p', name)]
    out = subprocess.run([sys.executable, '-m', 'mypy', '--config-file', 'mypy.ini',
                          '--cache-dir', '/dev/null', *packages], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr


# Where each package's sources are, and what makes a module a ROS module: it imports rclpy, a
# message package or a ROS 2 library that needs a running graph.
SOURCES = {name: ROOT / name / name for name in PACKAGES if name != 'sim_bringup'}
SOURCES['sim_bringup'] = ROOT / 'ros_ws' / 'src' / 'sim_bringup' / 'sim_bringup'
ROS_IMPORTS = ('rclpy', 'sim_interfaces', 'builtin_interfaces', 'action_msgs',
               'rcl_interfaces', 'launch', 'launch_ros', 'tf2_ros', 'rosidl_runtime_py')


def _modules():
    for source in SOURCES.values():
        for path in sorted(source.rglob('*.py')):
            parts = path.relative_to(source.parent).with_suffix('').parts
            yield '.'.join(parts[:-1] if parts[-1] == '__init__' else parts), path


def _imports_ros(path) -> bool:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
    tops = {name.split('.')[0] for name in names}
    return any(top in ROS_IMPORTS or top.endswith(('_msgs', '_srvs')) for top in tops)


def test_every_ros_free_module_is_checked_strictly():
    """mypy.ini's strict section names every module that imports no ROS: a new ROS-free module
    is strict from its first commit (the nodes, which import rclpy, are checked, not strictly:
    rclpy's Python API ships no types)."""
    config = configparser.ConfigParser()
    config.read(ROOT / 'mypy.ini')
    strict = [pattern for section in config.sections() if section.startswith('mypy-')
              and config[section].get('disallow_untyped_defs') == 'True'
              for pattern in section[len('mypy-'):].split(',')]
    modules = dict(_modules())
    assert len(modules) > 100 and 'trial_record.result' in modules
    assert {'studies', 'sim_bringup', 'coordinator'} <= set(PACKAGES)
    loose = [name for name, path in modules.items() if not _imports_ros(path)
             and not any(fnmatch.fnmatchcase(name, pattern) for pattern in strict)]
    assert not loose, f'ROS-free modules that mypy.ini does not check strictly: {loose}'
    ros = [name for name, path in modules.items() if _imports_ros(path)]
    assert 'sim_bridge.sim_node' in ros and 'coordinator.coordinator_node' in ros
