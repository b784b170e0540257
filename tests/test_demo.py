"""The main job, as a user runs it: the README's `make demo`, here via its script."""
import os
import re
import subprocess

from helpers import ROOT


def test_demo_drives_the_square_and_passes():
    env = {**os.environ, 'DEMO_REAL_TIME_FACTOR': '4.0'}
    env.pop('ROS_DOMAIN_ID', None)  # the demo picks its own
    out = subprocess.run(['bash', str(ROOT / 'scripts' / 'demo.sh')], env=env,
                         capture_output=True, text=True, timeout=300)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-3000:]
    assert '[demo] PASS' in text
    error = re.search(r'error: position ([0-9.]+) mm', text)
    assert error and float(error.group(1)) < 50.0
