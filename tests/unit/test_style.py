"""Style: ruff, with the rule set of ruff.toml (ament's 99 columns among them), on every Python
file of the project."""
import subprocess
import sys

from helpers import ROOT


def test_ruff_finds_nothing():
    out = subprocess.run([sys.executable, '-m', 'ruff', 'check', '--no-cache',
                          '--output-format', 'concise', '.'], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stdout + out.stderr
