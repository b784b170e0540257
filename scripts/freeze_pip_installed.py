"""Print exact pins of the distributions pip installed in this environment.

The ROS wheels carry further distributions inside themselves (rclpy, std_msgs, ...) as
.egg-info directories without an INSTALLER file; those are not on the package index and are
pinned by the wheel that carries them, so they are left out.
"""
import importlib.metadata as md
import sys

SKIP = {'pip'}


def main() -> int:
    pins = set()
    for dist in md.distributions():
        name = dist.metadata['Name']
        if (dist.read_text('INSTALLER') or '').strip() != 'pip' or name.lower() in SKIP:
            continue
        pins.add(f'{name}=={dist.version}')
    print('\n'.join(sorted(pins, key=str.lower)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
