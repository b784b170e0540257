"""The main job, as a user runs it: the README's `make demo`, here via its script."""
import os
import re
import subprocess

from helpers import ROOT


def _assert_live_view(text, run, topic):
    """The demo started the Foxglove bridge on its graph, said where, and ended it."""
    assert re.search(r'\[demo\] live view: in Foxglove, .* ws://127\.0\.0\.1:\d+', text), text
    log = (run / 'live_view.log').read_text()
    assert f'advertising {topic}' in log and '[live_view] served' in log, log[-2000:]


def test_demo_drives_the_square_records_and_passes(tmp_path):
    # The demo's own pace (real time): the scripted teleop is open loop, so its segment
    # switches lag by its /clock latency times the real-time factor.
    env = {**os.environ, 'DEMO_RUNS_DIR': str(tmp_path), 'DEMO_LIVE_VIEW_PORT': '0'}
    env.pop('ROS_DOMAIN_ID', None)  # the demo picks its own
    out = subprocess.run(['bash', str(ROOT / 'scripts' / 'demo_mini_robot.sh')], env=env,
                         capture_output=True, text=True, timeout=600)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-1500:]
    assert '[demo] PASS' in text
    _assert_live_view(text, next(tmp_path.glob('demo-*')), '/mini_robot/odom')
    error = re.search(r'error: position ([0-9.]+) mm', text)
    assert error and float(error.group(1)) < 50.0
    # The run was recorded and analysed.
    run = next(tmp_path.glob('demo-*'))
    assert (run / 'bag' / 'metadata.yaml').is_file()
    report = (run / 'report' / 'report.md').read_text()
    assert '/mini_robot/odom' in report and (run / 'report' / 'paths.png').is_file()


def test_the_pipeline_demo_runs_the_scenario_prints_its_table_and_records(tmp_path):
    env = {**os.environ, 'DEMO_RUNS_DIR': str(tmp_path), 'DEMO_LIVE_VIEW_PORT': '0'}
    env.pop('ROS_DOMAIN_ID', None)
    out = subprocess.run(['bash', str(ROOT / 'scripts' / 'demo.sh')], env=env,
                         capture_output=True, text=True, timeout=900)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-2500:]
    assert '[demo] PASS' in text
    _assert_live_view(text, next(tmp_path.glob('pipeline-*')), '/belt_camera/image_raw')
    # The results table beside the paper's rows, with every material delivered.
    row = re.search(r'\| \*\*these trials\*\* \| 1 \| ([0-9.]+) .*\| ([0-9.]+) \| ([0-9.]+) \| '
                    r'([0-9.]+) \|', text)
    assert row, text[-2500:]
    assert [float(v) for v in row.groups()[1:]] == [100.0, 100.0, 100.0]
    assert '| paper, trials 100-110 | | 61 |' in text
    run = next(tmp_path.glob('pipeline-*'))
    assert (run / 'trial_000' / 'bag' / 'metadata.yaml').is_file()
    assert (run / 'report.md').is_file() and (run / 'youbot_paths.png').is_file()
    # The report shows the run at its phases, drawn from the bag (sim_bringup's storyboard).
    assert '![storyboard](storyboard.png)' in (run / 'report.md').read_text()
    assert (run / 'storyboard.png').stat().st_size > 100_000
    # The bag decodes with mcap-ros2-support (no code shared with the writer) and holds the
    # cell's TF tree, one tree under world, and both robots' descriptions.
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    edges, descriptions = set(), {}
    with open(run / 'trial_000' / 'bag' / 'bag.mcap', 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, msg in reader.iter_decoded_messages(topics=[
                '/tf', '/tf_static', '/youbot/robot_description', '/zu12/robot_description']):
            if channel.topic.startswith('/tf'):
                edges |= {(t.header.frame_id, t.child_frame_id) for t in msg.transforms}
            else:
                descriptions[channel.topic] = msg.data
    parents, children = {p for p, _ in edges}, {c for _, c in edges}
    assert parents - children == {'world'}
    assert {('world', 'youbot/odom'), ('youbot/odom', 'youbot/base_link'),
            ('world', 'zu12/base_link'), ('world', 'belt_camera_optical_frame'),
            ('zu12/link_6', 'zu12/flange')} <= edges
    assert all('<robot' in d for d in descriptions.values()) and len(descriptions) == 2
