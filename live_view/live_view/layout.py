"""A Foxglove layout for a world: what a person watching the live view (or a bag) wants to see
of the cell, made from the world file, so that a cell with other robots or more of them is
shown whole.

``live_view_layout WORLD [-o FILE]`` writes it (standard output without ``-o``); import it in
Foxglove (Layouts, Import from file). It has: a 3D panel with the grid and every robot drawn
from its ``robot_description``, the materials' markers; the first camera's image; a plot of each
mobile base's forward and turn speed from its odometry; and the pipeline coordinator's state and
events. ``layouts/pipeline_cell.json`` is this layout for the paper's cell.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from world_description.world_config import WorldConfig, WorldConfigError, load_world

MATERIALS_TOPIC = '/cell/materials'
COORDINATOR = '/coordinator_node'


def _topic(namespace: str, name: str) -> str:
    ns = namespace.strip('/')
    return f'/{ns}/{name}' if ns else f'/{name}'


def _camera_topic(world: WorldConfig) -> Optional[str]:
    """The first camera's image topic (a camera on a robot is in the robot's namespace)."""
    if not world.cameras:
        return None
    cam = world.cameras[0]
    ns = next((r.namespace for r in world.robots if r.name == cam.robot), '') if cam.robot else ''
    return _topic(ns, f'{cam.name}/image_raw')


def foxglove_layout(world: WorldConfig) -> Dict[str, Any]:
    """The layout (Foxglove's layout JSON, as a mapping) for ``world``'s robots and cameras."""
    descriptions = {r.name: _topic(r.namespace, 'robot_description') for r in world.robots}
    layers: Dict[str, Any] = {'grid': {
        'layerId': 'foxglove.Grid', 'visible': True, 'frameId': 'world', 'size': 6,
        'divisions': 12, 'position': [0, 0, 0]}}
    layers.update({name: {'layerId': 'foxglove.Urdf', 'visible': True, 'sourceType': 'topic',
                          'topic': t, 'framePrefix': ''} for name, t in descriptions.items()})
    speeds: List[Dict[str, Any]] = []
    for r in world.robots:
        if r.drive is not None:
            odom = _topic(r.namespace, 'odom')
            speeds += [{'value': f'{odom}.twist.twist.{axis}', 'enabled': True,
                        'timestampMethod': 'receiveTime'}
                       for axis in ('linear.x', 'angular.z')]
    panels: Dict[str, Any] = {
        '3D!cell': {
            'cameraState': {'distance': 4.5, 'perspective': True, 'phi': 55, 'thetaOffset': 35,
                            'target': [0, 0.3, 0], 'targetOffset': [0, 0, 0], 'fovy': 45,
                            'near': 0.01, 'far': 100, 'targetOrientation': [0, 0, 0, 1]},
            'followMode': 'follow-none', 'followTf': 'world', 'scene': {'enableStats': False},
            'transforms': {'showLabel': False, 'axisScale': 0.5},
            'topics': {MATERIALS_TOPIC: {'visible': True},
                       **{t: {'visible': True} for t in descriptions.values()}},
            'layers': layers}}
    side: List[Any] = []
    image = _camera_topic(world)
    if image:
        panels['Image!belt'] = {'imageMode': {'imageTopic': image}}
        side.append('Image!belt')
    if speeds:
        panels['Plot!speeds'] = {'paths': speeds, 'showLegend': True, 'xAxisVal': 'timestamp'}
        side.append('Plot!speeds')
    for name, t in (('state', 'state'), ('events', 'events')):
        panels[f'RawMessages!{name}'] = {'topicPath': f'{COORDINATOR}/{t}',
                                         'diffEnabled': False, 'expansion': 'all'}
    side.append({'direction': 'row', 'first': 'RawMessages!state',
                 'second': 'RawMessages!events'})
    return {'configById': panels, 'globalVariables': {}, 'userNodes': {},
            'playbackConfig': {'speed': 1},
            'layout': {'direction': 'row', 'first': '3D!cell', 'second': _column(side),
                       'splitPercentage': 58}}


def _column(items: Sequence[Any]) -> Any:
    """Panels one above the other: the first 40 % (then 45 %) of what is left."""
    if len(items) == 1:
        return items[0]
    return {'direction': 'column', 'first': items[0], 'second': _column(items[1:]),
            'splitPercentage': 40 if len(items) > 2 else 45}


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog='live_view_layout', description='Write a Foxglove layout for a world file: every '
        'robot in 3D, the first camera, each mobile base\'s speeds, the coordinator\'s state '
        'and events.')
    parser.add_argument('world', help='the world file (a path or package://...)')
    parser.add_argument('-o', '--output', help='the layout file to write (default: stdout)')
    args = parser.parse_args(argv)
    try:
        world = load_world(args.world)
    except (WorldConfigError, OSError) as exc:
        print(f'live_view_layout: {exc}', file=sys.stderr)
        return 2
    text = json.dumps(foxglove_layout(world), indent=2) + '\n'
    if not args.output:
        sys.stdout.write(text)
        return 0
    try:
        Path(args.output).write_text(text)
    except OSError as exc:
        print(f'live_view_layout: cannot write {args.output}: {exc}', file=sys.stderr)
        return 2
    print(f'live_view_layout: {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
