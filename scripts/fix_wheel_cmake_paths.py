"""Point the ROS wheels' CMake exports at this machine's Python and numpy headers.

The ros-jazzy-* wheels are built on a manylinux host, and their generated
``share/*/cmake/*.cmake`` files name that host's interpreter, e.g.
``/opt/python/cp311-cp311/include/python3.11``.  rosidl's Python type support for a custom
interface package links against those targets, so without this rewrite ``colcon build`` of an
interface package fails with "Imported target includes non-existent path".
"""
import re
import sys
import sysconfig
from pathlib import Path

import numpy

HOST_ROOT = re.compile(r'/opt/python/cp3\d+-cp3\d+')


def local_paths() -> dict:
    version = f'{sys.version_info.major}.{sys.version_info.minor}'
    return {
        f'/include/python{version}': sysconfig.get_paths()['include'],
        f'/lib/python{version}/site-packages/numpy/_core/include': numpy.get_include(),
    }


def rewrite(text: str, replacements: dict) -> str:
    """Replace '<host root><suffix>' by the local directory; leave other mentions alone."""
    for suffix, local in replacements.items():
        text = re.sub(HOST_ROOT.pattern + re.escape(suffix), lambda _m, p=local: p, text)
    return text


def main(argv: list) -> int:
    if len(argv) != 2:
        print('usage: fix_wheel_cmake_paths.py VENV_PREFIX', file=sys.stderr)
        return 2
    prefix = Path(argv[1])
    replacements = local_paths()
    for local in replacements.values():
        if not Path(local).is_dir():
            print(f'error: local include directory {local} does not exist', file=sys.stderr)
            return 1
    changed = 0
    for cmake_file in sorted(prefix.glob('share/*/cmake/*.cmake')):
        text = cmake_file.read_text()
        if '/opt/python/cp3' not in text:
            continue
        new = rewrite(text, replacements)
        if new != text:
            cmake_file.write_text(new)
            changed += 1
    print(f'[setup] rewrote build-host Python paths in {changed} CMake files')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
