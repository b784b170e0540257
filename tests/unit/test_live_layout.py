"""The Foxglove layout made from a world file (``live_view_layout``): every robot of the world in
3D, each mobile base's speeds, the first camera in its robot's namespace; the committed layout is
the paper's cell's."""
import json
from pathlib import Path

from live_view.layout import foxglove_layout, main
from world_description.resources import resolve_resource
from world_description.world_config import load_world

LAYOUTS = Path(__file__).resolve().parents[2] / 'live_view' / 'layouts'


def world(name):
    return load_world(resolve_resource(f'package://world_description/worlds/{name}.yaml'))


def test_the_committed_layout_is_the_papers_cell_made_from_its_world():
    made = foxglove_layout(world('pipeline_cell'))
    assert made == json.loads((LAYOUTS / 'pipeline_cell.json').read_text())


def test_a_fleets_layout_draws_and_plots_every_youbot():
    made = foxglove_layout(world('cell_two_youbots'))
    view = made['configById']['3D!cell']
    urdfs = {k: v['topic'] for k, v in view['layers'].items() if v['layerId'] == 'foxglove.Urdf'}
    assert urdfs == {'zu12': '/zu12/robot_description', 'youbot': '/youbot/robot_description',
                     'youbot2': '/youbot2/robot_description'}
    assert set(urdfs.values()) <= set(view['topics'])
    plotted = [p['value'] for p in made['configById']['Plot!speeds']['paths']]
    assert plotted == [f'/{r}/odom.twist.twist.{a}' for r in ('youbot', 'youbot2')
                       for a in ('linear.x', 'angular.z')]


def test_a_camera_on_a_robot_is_shown_in_its_namespace_and_every_panel_is_placed(tmp_path):
    w = world('mini_robot')
    made = foxglove_layout(w)
    cam = w.cameras[0]
    ns = next(r.namespace for r in w.robots if r.name == cam.robot).strip('/')
    assert made['configById']['Image!belt']['imageMode']['imageTopic'] == \
        f'/{ns}/{cam.name}/image_raw'

    def placed(node):
        return [node] if isinstance(node, str) else placed(node['first']) + placed(
            node['second'])
    assert sorted(placed(made['layout'])) == sorted(made['configById'])
    out = tmp_path / 'mini.json'
    assert main([str(resolve_resource('package://world_description/worlds/mini_robot.yaml')),
                 '-o', str(out)]) == 0
    assert json.loads(out.read_text()) == made


def test_a_world_that_cannot_be_read_is_one_line(tmp_path, capsys):
    assert main([str(tmp_path / 'none.yaml')]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('live_view_layout: ') and '\n' not in err


def test_a_world_named_by_its_package_is_read(tmp_path, capsys):
    """`live_view_layout package://...` said the file did not exist (issue 62)."""
    out = tmp_path / 'cell.json'
    assert main(['package://world_description/worlds/pipeline_cell.yaml', '-o', str(out)]) == 0
    assert json.loads(out.read_text()) == foxglove_layout(load_world(resolve_resource(
        'package://world_description/worlds/pipeline_cell.yaml')))
    assert main(['package://no_such_package/worlds/x.yaml']) == 2
    assert 'package "no_such_package" not found' in capsys.readouterr().err
