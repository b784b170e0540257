"""``generate_urdf``: write the Zu 12's and the youBot's URDFs from the numbers in
``controllers`` (the DH and MDH tables, limits, masses), or check that the committed files are
what the generators write.

    generate_urdf [zu12] [youbot] [--check] [--out DIR]

Without ``--out`` the files go into this package's source tree (``robot_description/urdf``),
which is where they are committed; an installed package has no source tree, and needs
``--out``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Dict, Optional, Sequence

from robot_description import youbot_urdf, zu12_urdf

GENERATORS: Dict[str, Callable[[], str]] = {'zu12': zu12_urdf.render,
                                            'youbot': youbot_urdf.render}
_SOURCE = Path(__file__).resolve().parent.parent


def source_urdf_dir() -> Optional[Path]:
    """The package's source ``urdf`` directory, if this module runs from a source tree."""
    return _SOURCE / 'urdf' if (_SOURCE / 'package.xml').is_file() else None


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='generate_urdf',
                                     description=(__doc__ or '').splitlines()[0])
    parser.add_argument('robots', nargs='*', metavar='ROBOT',
                        help=f'the robots to write ({", ".join(GENERATORS)}; all by default)')
    parser.add_argument('--check', action='store_true',
                        help='exit 1 if a file differs from what its generator writes')
    parser.add_argument('--out', type=Path, default=None,
                        help='the directory of the URDFs (this package\'s source tree)')
    args = parser.parse_args(argv)
    unknown = sorted(set(args.robots) - set(GENERATORS))
    if unknown:
        parser.error(f'no generator for {", ".join(unknown)}: the robots are '
                     f'{", ".join(GENERATORS)}')
    out = args.out or source_urdf_dir()
    if out is None or not out.is_dir():
        parser.error(f'{out or "the package source tree"} is not a directory: give --out DIR')
    status = 0
    for robot in args.robots or list(GENERATORS):
        path, text = out / f'{robot}.urdf', GENERATORS[robot]()
        if args.check:
            same = path.is_file() and path.read_text() == text
            print(f'{path}: {"up to date" if same else "differs from the generator"}')
            status = status or (0 if same else 1)
        else:
            path.write_text(text)
            print(f'wrote {path}')
    return status


if __name__ == '__main__':
    sys.exit(main())
