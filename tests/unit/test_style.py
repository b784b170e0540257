"""The ament line limit (99 columns) on every Python file of the project."""
import subprocess

from helpers import ROOT


def test_python_lines_fit_in_99_columns():
    files = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard',
                            '*.py'], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    assert files
    long_lines = [f'{name}:{i}' for name in files
                  for i, line in enumerate((ROOT / name).read_text().splitlines(), 1)
                  if len(line) > 99]
    assert long_lines == []
