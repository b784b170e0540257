"""A URDF that a client asks the simulator to spawn, checked before PyBullet reads it: bounded
in size, parsed once by expat (linear in its length; no document type, so no entity expansion),
a ``<robot>`` of a bounded number of links and joints, and meshes that are regular files of a
bounded size. Any client on the DDS domain can send one: nothing here may take more than
milliseconds, whatever the text."""
from __future__ import annotations

import math
import os
import stat
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional, Tuple

MAX_URDF_BYTES = 1024 * 1024      # the project's URDFs are 8-16 kB
MAX_LINKS = 128                   # and joints: the youBot has 19 links
MAX_ELEMENTS = 20_000             # every XML element
MAX_DEPTH = 32                    # elements nested in one another
MAX_MESH_BYTES = 32 * 1024 * 1024
MESH_SUFFIXES = ('.obj', '.stl', '.dae')      # what PyBullet's URDF importer reads


class UrdfProblem(ValueError):
    """A URDF that is not spawned; ``code``: parse_error, not_found or unsupported_format."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str                          # revolute, continuous, prismatic, fixed, ...
    lower: float                       # its <limit>'s (-inf, inf: none given)
    upper: float
    velocity: float = 0.0              # its <limit>'s speed limit (0: none given)


@dataclass(frozen=True)
class UrdfSummary:
    name: str                          # the robot's name ('' if it has none)
    links: int
    joints: int
    meshes: Tuple[str, ...]            # the mesh file names, as written
    joint_list: Tuple[UrdfJoint, ...] = ()
    link_names: Tuple[str, ...] = ()

    def joint(self, name: str) -> Optional[UrdfJoint]:
        return next((j for j in self.joint_list if j.name == name), None)


def read_urdf_file(path: Path) -> str:
    """A URDF file's text, read no further than ``MAX_URDF_BYTES`` (a regular file only: a
    FIFO or a device named ``.urdf`` would block the reader)."""
    _regular_file(path, str(path), MAX_URDF_BYTES)
    try:
        with open(path, 'rb') as f:
            data = f.read(MAX_URDF_BYTES + 1)
    except OSError as exc:
        raise UrdfProblem('not_found', f'{path}: {exc.strerror or exc}') from None
    if len(data) > MAX_URDF_BYTES:
        raise UrdfProblem('parse_error', f'{path} grew past {MAX_URDF_BYTES} bytes')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise UrdfProblem('parse_error', f'{path} is not UTF-8 (byte {exc.start})') from None


def summarise_urdf(text: str) -> UrdfSummary:
    """The URDF's robot name, links, joints and meshes; UrdfProblem if it is too large, not
    well-formed XML, has a document type, or is no ``<robot>``."""
    size = len(text.encode('utf-8', errors='replace'))
    if size > MAX_URDF_BYTES:
        raise UrdfProblem('parse_error', f'the URDF has {size} bytes; at most {MAX_URDF_BYTES} '
                          'here')
    walk = _Walk()
    parser = xml.parsers.expat.ParserCreate()
    parser.StartDoctypeDeclHandler = walk.doctype
    parser.EntityDeclHandler = walk.entity
    parser.StartElementHandler = walk.start
    parser.EndElementHandler = walk.end
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise UrdfProblem('parse_error', f'the URDF is not well-formed XML: '
                          f'{xml.parsers.expat.ErrorString(exc.code)} at line {exc.lineno}, '
                          f'column {exc.offset}') from None
    if walk.root != 'robot':
        raise UrdfProblem('parse_error', f'the URDF\'s root element is <{walk.root}>, not '
                          '<robot>')
    return UrdfSummary(walk.name, walk.links, walk.joints, tuple(walk.meshes),
                       tuple(walk.joint_list), tuple(walk.link_names))


class _Walk:
    """expat's callbacks: counts and bounds (a problem ends the parse at once)."""

    def __init__(self) -> None:
        self.root = ''
        self.name = ''
        self.links = self.joints = self.elements = self.depth = 0
        self.meshes: List[str] = []
        self.joint_list: List[UrdfJoint] = []
        self.link_names: List[str] = []

    def doctype(self, *_args: object) -> None:
        raise UrdfProblem('parse_error', 'the URDF has a document type (<!DOCTYPE>): not '
                          'taken here (entity expansion)')

    def entity(self, *_args: object) -> None:
        raise UrdfProblem('parse_error', 'the URDF declares entities: not taken here')

    def start(self, tag: str, attributes: Dict[str, str]) -> None:
        self.elements += 1
        self.depth += 1
        if self.elements > MAX_ELEMENTS:
            raise UrdfProblem('parse_error', f'the URDF has more than {MAX_ELEMENTS} elements')
        if self.depth > MAX_DEPTH:
            raise UrdfProblem('parse_error', f'the URDF nests elements more than {MAX_DEPTH} '
                              'deep')
        if not self.root:
            self.root, self.name = tag, str(attributes.get('name', ''))
        elif self.depth == 2 and tag in ('link', 'joint'):
            if tag == 'link':
                self.links += 1
                self.link_names.append(str(attributes.get('name', '')))
            else:
                self.joints += 1
                self.joint_list.append(UrdfJoint(str(attributes.get('name', '')),
                                                 str(attributes.get('type', '')),
                                                 -math.inf, math.inf))
            if max(self.links, self.joints) > MAX_LINKS:
                raise UrdfProblem('parse_error', f'the URDF has more than {MAX_LINKS} {tag}s')
        elif tag == 'mesh':
            self.meshes.append(str(attributes.get('filename', '')))
        elif tag == 'limit' and self.depth == 3 and self.joint_list:
            last = self.joint_list[-1]
            self.joint_list[-1] = UrdfJoint(last.name, last.kind,
                                            _float(attributes.get('lower'), -math.inf),
                                            _float(attributes.get('upper'), math.inf),
                                            _float(attributes.get('velocity'), 0.0))

    def end(self, _tag: str) -> None:
        self.depth -= 1


def _float(text: Optional[str], default: float) -> float:
    try:
        return float(text) if text is not None else default
    except ValueError:
        return default


def check_meshes(summary: UrdfSummary, base_dir: Optional[Path],
                 resolve: Callable[[str], Path]) -> None:
    """Every mesh a URDF names is a regular file of at most ``MAX_MESH_BYTES`` that PyBullet
    reads (``resolve`` turns a ``package://`` name into a path; ``base_dir``: where a relative
    name is, None for a URDF sent as text, which has no directory)."""
    for name in summary.meshes:
        if not name:
            raise UrdfProblem('parse_error', 'a <mesh> has no filename')
        if not name.lower().endswith(MESH_SUFFIXES):
            raise UrdfProblem('unsupported_format', f'mesh {name[:200]!r}: the meshes read '
                              f'here are {", ".join(MESH_SUFFIXES)}')
        if name.startswith('package://'):
            try:
                path = resolve(name)
            except (ValueError, KeyError, OSError) as exc:
                # PyBullet reads package://a/b as a/b beside the URDF (its bundled models'
                # meshes are named so): found there, it is that file.
                beside = None if base_dir is None else base_dir / name[len('package://'):]
                if beside is None or not beside.is_file():
                    raise UrdfProblem('not_found', f'mesh {name[:200]}: {exc}') from None
                path = beside
        else:
            path = Path(name[len('file://'):] if name.startswith('file://') else name)
            if not path.is_absolute():
                if base_dir is None:
                    raise UrdfProblem('not_found', f'mesh {name[:200]!r}: a URDF sent as text '
                                      'names its meshes by absolute path, file:// or '
                                      'package://')
                path = base_dir / path
        _regular_file(path, f'mesh {name[:200]}', MAX_MESH_BYTES)


def _regular_file(path: Path, what: str, limit: int) -> None:
    """UrdfProblem unless ``path`` is a regular file of at most ``limit`` bytes."""
    try:
        info = os.stat(path)
    except OSError as exc:
        raise UrdfProblem('not_found', f'{what}: {exc.strerror or exc}') from None
    if not stat.S_ISREG(info.st_mode):
        raise UrdfProblem('not_found', f'{what} is not a regular file')
    if info.st_size > limit:
        raise UrdfProblem('parse_error', f'{what} has {info.st_size} bytes; at most {limit} '
                          'here')
