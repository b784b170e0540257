"""Reading a world file: its size and YAML checked, the worlds it ``extends`` merged under it,
then its sections parsed (world_sections.py)."""
from __future__ import annotations

import stat
from pathlib import Path
from typing import Any, Dict, Hashable, Tuple

import yaml

from world_description.errors import WorldConfigError
from world_description.resources import PYBULLET_DATA, resolve_resource
from world_description.world_schema import WorldConfig
from world_description.world_sections import parse_world

# A world file larger than this is refused before it is parsed: the worlds here are a few kB,
# and YAML is parsed at about 2 MB/s by each node that reads it (a 1 GB file took 8.5 min and
# 2.2 GB per node).
MAX_WORLD_BYTES = 4 * 1024 * 1024


# Values (numbers, strings, entries) of a world once YAML's aliases are expanded: the largest
# shipped world has about 300.
MAX_WORLD_VALUES = 100_000


# A world may extend another, which may extend another, this deep at most.
MAX_EXTENDS = 8


def load_world(path: str | Path) -> WorldConfig:
    """A world file (a path, or as a user names it: ``package://``, ``file://``), read and
    checked. One that ``extends`` another (a path relative to it, or ``package://``) is that
    world with its own keys merged in: a mapping key by key, any other value (a list too)
    replacing the base's; ``more_obstacles`` are added to the base's obstacles, and
    ``materials.classes`` replaces the base's ``counts`` and ``colors``."""
    path = _located(path)
    return parse_world(_resolved(path, read_yaml(path), (path.resolve(),)), str(path))


def world_data(path: str | Path) -> Dict[str, Any]:
    """A world file as one mapping, the worlds it extends merged in (what ``load_world``
    parses): a world as it was, to run it again. Checked as load_world checks it."""
    path = _located(path)
    data = _resolved(path, read_yaml(path), (path.resolve(),))
    parse_world(data, str(path))
    return _absolute_resources(dict(data), path.resolve().parent)


def _located(world: str | Path) -> Path:
    """A world named as a user names it (a ``package://`` address too) or a path: its file."""
    return resolve_resource(world) if isinstance(world, str) else Path(world)


def _absolute_resources(data: Dict[str, Any], base_dir: Path) -> Dict[str, Any]:
    """``data`` with its robots' relative resource paths (a URDF, joint limits) made absolute
    from ``base_dir``, as the simulator resolves them: the mapping runs from anywhere."""
    def absolute(holder: Any, key: str) -> None:
        value = holder.get(key) if isinstance(holder, dict) else None
        if isinstance(value, str) and not value.startswith(('package://', PYBULLET_DATA)):
            rel = value[len('file://'):] if value.startswith('file://') else value
            if not Path(rel).is_absolute():
                holder[key] = str(base_dir / rel)
    # (Also before the world is checked: what is not a list of mappings is left as it is,
    # for parse_world to refuse.)
    robots = data.get('robots')
    for robot in robots if isinstance(robots, list) else []:
        absolute(robot, 'urdf')
        controllers = robot.get('controllers') if isinstance(robot, dict) else None
        for controller in controllers if isinstance(controllers, list) else []:
            absolute(controller, 'joint_limits')
    return data


class _Loader(yaml.SafeLoader):  # type: ignore[misc]
    """YAML's safe loader that refuses a mapping giving a key twice: YAML forbids it, and
    PyYAML would keep the last silently (a factor or a robot given twice, one of them lost)."""


def _mapping(loader: _Loader, node: yaml.MappingNode, deep: bool = False) -> Dict[Any, Any]:
    seen = set()
    for key_node, _ in node.value:
        if key_node.tag == 'tag:yaml.org,2002:merge':
            continue             # (``<<: *base``: its keys may be given again, to override)
        key = loader.construct_object(key_node, deep=True)
        if isinstance(key, Hashable):
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f'the key {str(key)[:80]!r} is given twice in one mapping',
                    key_node.start_mark)
            seen.add(key)
    mapping: Dict[Any, Any] = loader.construct_mapping(node, deep=deep)
    return mapping


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def read_yaml(path: Path, what: str = 'world file') -> Any:
    """A YAML file of at most MAX_WORLD_BYTES (and MAX_WORLD_VALUES once expanded), read;
    WorldConfigError with one line naming it (``what``) otherwise."""
    try:
        info = path.stat()
    except FileNotFoundError:
        raise WorldConfigError(f'{what} {path} does not exist') from None
    except OSError as exc:          # (a symbolic link loop, a directory that cannot be read)
        raise WorldConfigError(f'{what} {path}: {exc.strerror}') from None
    if stat.S_ISDIR(info.st_mode):
        raise WorldConfigError(f'{what} {path} is a directory')
    if not stat.S_ISREG(info.st_mode):
        raise WorldConfigError(f'{what} {path} is not a regular file')
    if info.st_size > MAX_WORLD_BYTES:
        raise WorldConfigError(f'{what} {path} has {info.st_size} bytes; a {what} is '
                               f'at most {MAX_WORLD_BYTES} bytes')
    try:
        data = yaml.load(path.read_text(encoding='utf-8'), Loader=_Loader)
        _check_expanded_size(data, path)
        return data
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise WorldConfigError(f'{path}: not valid YAML{where}: {problem}') from None
    except RecursionError:
        raise WorldConfigError(f'{path}: nested too deeply') from None
    except UnicodeDecodeError as exc:
        raise WorldConfigError(f'{path}: not UTF-8 text (byte {exc.start}: '
                               f'{exc.object[exc.start:exc.start + 1]!r})') from None
    except OSError as exc:
        raise WorldConfigError(f'{path}: cannot be read ({exc.strerror})') from None




def _check_expanded_size(data: Any, path: Path) -> None:
    """A world's values, counted as they expand: YAML's aliases let a few kilobytes stand for
    billions of values (the "billion laughs"), which every copy of the world (a result, a bag's
    record, a sweep's point) would write out."""
    count, stack = 0, [data]
    while stack:
        value = stack.pop()
        count += 1
        if count > MAX_WORLD_VALUES:
            raise WorldConfigError(f'{path}: more than {MAX_WORLD_VALUES} values once its YAML '
                                   'aliases are expanded')
        if isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)


def _resolved(path: Path, data: Any, seen: Tuple[Path, ...]) -> Any:
    """``data`` with the world it extends merged under it (see load_world)."""
    if not isinstance(data, dict) or 'extends' not in data:
        if isinstance(data, dict) and 'more_obstacles' in data:
            raise WorldConfigError(f'{path}: more_obstacles needs a world it extends')
        return data
    uri = data['extends']
    if not isinstance(uri, str) or not uri:
        raise WorldConfigError(f'{path}: extends must name a world file, got {uri!r}')
    base_path = resolve_resource(uri, path.parent)
    if base_path.resolve() in seen:
        raise WorldConfigError(f'{path}: extends {uri}, which extends it again')
    if len(seen) > MAX_EXTENDS:
        raise WorldConfigError(f'{path}: worlds extend each other more than {MAX_EXTENDS} deep')
    base = _resolved(base_path, read_yaml(base_path), seen + (base_path.resolve(),))
    if not isinstance(base, dict):
        raise WorldConfigError(f'{base_path}: the top level must be a mapping')
    # (The base's own relative files are relative to the base, wherever the world that
    # extends it is: a sweep's point, or a re-run's world, in a trial's directory.)
    base = _absolute_resources(base, base_path.resolve().parent)
    own = {k: v for k, v in data.items() if k not in ('extends', 'more_obstacles')}
    more = data.get('more_obstacles') or []
    if not isinstance(more, list):
        raise WorldConfigError(f'{path}: more_obstacles must be a list')
    merged = _merge(base, own)
    if isinstance(own.get('materials'), dict) and 'classes' in own['materials']:
        for key in ('counts', 'colors'):
            if key not in own['materials']:
                merged['materials'].pop(key, None)
    if more:
        obstacles = merged.get('obstacles') or []
        if not isinstance(obstacles, list):
            raise WorldConfigError(f'{path}: obstacles must be a list')
        merged['obstacles'] = list(obstacles) + more
    return merged


def _merge(base: Any, own: Any) -> Any:
    if isinstance(base, dict) and isinstance(own, dict):
        out = dict(base)
        for key, value in own.items():
            out[key] = _merge(base[key], value) if key in base else value
        return out
    return own
