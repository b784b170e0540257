"""Style and types: ruff (ruff.toml's rules, ament's 99 columns among them) on every Python file
of the project, and mypy (mypy.ini)."""
import subprocess
import sys

from helpers import ROOT


def test_ruff_finds_nothing():
    out = subprocess.run([sys.executable, '-m', 'ruff', 'check', '--no-cache',
                          '--output-format', 'concise', '.'], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr


# Every package of the project (mypy.ini: strict on the ROS-free floor).
PACKAGES = ('controllers', 'world_description', 'coordinator', 'perception', 'recording',
            'sim_bridge', 'arm_kinematics', 'ros_common', 'teleop', 'sim_bringup', 'live_view')


def test_mypy_finds_nothing():
    packages = [arg for name in PACKAGES for arg in ('-p', name)]
    out = subprocess.run([sys.executable, '-m', 'mypy', '--config-file', 'mypy.ini',
                          '--cache-dir', '/dev/null', *packages], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr
