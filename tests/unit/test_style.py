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


def test_mypy_finds_nothing():
    """mypy.ini: strict on the ROS-free floor (controllers, world_description)."""
    out = subprocess.run([sys.executable, '-m', 'mypy', '--config-file', 'mypy.ini',
                          '--cache-dir', '/dev/null', '-p', 'controllers', '-p',
                          'world_description'], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
