"""The pipeline cell over DDS: the vision node on the simulator's belt camera reports every
material of a scenario exactly once, with the right colour, where PyBullet has it."""
import time

import numpy as np
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
from sim_interfaces.msg import MaterialDetectionArray
from visualization_msgs.msg import MarkerArray

from helpers import latest_stamp, wait_for, wait_for_stamp
from ros_common.stamps import to_seconds

WORLD = 'world:=package://world_description/worlds/pipeline_cell.yaml'


@pytest.fixture
def cell(start_node):
    """The cell with its belt standing: a test starts it (``start_belt``) once its subscribers
    are up, so that no material passes the camera before anyone looks."""
    return start_node('sim_node', '-p', WORLD, '-p', 'real_time_factor:=3.0', '-p',
                      'belt_speed:=0.0', '-p', 'scenario_seed:=7', '-p', 'rtf_log_period:=2.0')


def start_belt(probe, speed):
    request = SetParameters.Request(parameters=[
        Parameter('belt_speed', Parameter.Type.DOUBLE, speed).to_parameter_msg()])
    reply = probe.call(SetParameters, '/sim_node/set_parameters', request)
    assert reply.results[0].successful, reply.results[0].reason


def test_vision_reports_every_material_once_with_its_colour(cell, start_node, probe):
    vision = start_node('vision_node', '-r', 'image_raw:=/belt_camera/image_raw', '-r',
                        'camera_info:=/belt_camera/camera_info', '-p', 'use_sim_time:=true')
    truth = probe.collect(MarkerArray, '/cell/materials')
    frames = probe.collect(MaterialDetectionArray, '/detections')
    debug = probe.collect(Image, '/debug_image', qos=qos_profile_sensor_data)
    wait_for(lambda: 'looking for' in vision.output(), 20.0, what='the vision node')
    # The vision node sees frames and the probe hears it: only then does the belt start.
    wait_for(lambda: debug and truth, 60.0, what='the first debug image')
    start_belt(probe, 0.2)
    # The first snapshot taken after the reply was taken on a moving belt.
    heard = len(truth)
    wait_for(lambda: len(truth) > heard, 10.0, what='the materials after the belt started')
    moving_from = to_seconds(truth[heard][1].markers[0].header.stamp)

    def all_past_the_camera():
        if not truth:
            return False
        markers = truth[-1][1].markers
        return len(markers) == 8 and all(m.pose.position.x > -0.1 for m in markers)
    wait_for(all_past_the_camera, 240.0, what='all eight materials past the camera')
    # The detections of the frames up to then, still on their way.
    wait_for_stamp(frames, latest_stamp(truth), what='the detections up to then')
    # Ground truth (10 Hz) carried forward to each frame's stamp at the belt speed. Frames
    # from before the belt ran at a steady speed count for identity and colour only.
    snapshots = [(to_seconds(m.markers[0].header.stamp), {mk.id: mk for mk in m.markers})
                 for _, m in list(truth) if m.markers]
    matches, worst = {}, 0.0
    for _, msg in list(frames):
        t = to_seconds(msg.header.stamp)
        before = [s for s in snapshots if s[0] <= t + 1e-9]
        if not before:
            continue
        ts, markers = before[-1]
        for det in msg.detections:
            def error(mk, t=t, ts=ts, det=det):
                moving = 0.2 * (t - ts) if mk.text == 'on_belt' and ts >= moving_from else 0.0
                return np.hypot(mk.pose.position.x + moving - det.position.x,
                                mk.pose.position.y - det.position.y)
            nearest = min(markers.values(), key=error)
            if ts >= moving_from:
                worst = max(worst, error(nearest))
            matches.setdefault(det.id, set()).add((nearest.id, nearest.ns, det.color))
    final = {m.id: m.ns for m in truth[-1][1].markers}
    assert len(final) == 8
    # Each reported id is one physical material, with that material's colour ...
    for det_id, pairs in matches.items():
        assert len(pairs) == 1, (det_id, pairs)
        (truth_id, truth_color, color), = pairs
        assert color == truth_color, (det_id, pairs)
    # ... and every material was reported under exactly one id.
    assert sorted(next(iter(p))[0] for p in matches.values()) == sorted(final)
    assert worst < 0.005
    assert debug, 'no debug image'
    assert vision.alive() and cell.alive()


def test_unusable_frames_are_rejected_with_a_warning(start_node, probe):
    from sensor_msgs.msg import CameraInfo
    vision = start_node('vision_node')
    wait_for(lambda: 'looking for' in vision.output(), 20.0, what='the vision node')
    image_pub = probe.node.create_publisher(Image, 'image_raw', qos_profile_sensor_data)
    info_pub = probe.node.create_publisher(CameraInfo, 'camera_info', qos_profile_sensor_data)
    # (A reader of its detections first: without one, the node takes no frames.)
    detections = probe.collect(MaterialDetectionArray, '/detections')
    wait_for(lambda: image_pub.get_subscription_count() and info_pub.get_subscription_count(),
             20.0, what='the vision node subscriptions')
    frame = Image(width=320, height=240, encoding='rgb8', step=960, data=bytes(960 * 240))

    def warned_without_info():
        image_pub.publish(frame)            # repeated: the first may precede the matching
        return 'no camera_info yet' in vision.output()
    wait_for(warned_without_info, 10.0, period=0.2, what='a warning')
    info = CameraInfo(width=320, height=240,
                      k=[290.0, 0.0, 160.0, 0.0, 290.0, 119.0, 0.0, 0.0, 1.0])
    bad = [(Image(width=320, height=240, encoding='mono8', step=320, data=bytes(320 * 240)),
            'encoding "mono8" rejected'),
           (Image(width=160, height=120, encoding='rgb8', step=480, data=bytes(480 * 120)),
            'frame 160x120 rejected'),
           (Image(width=320, height=240, encoding='rgb8', step=960), 'empty frame rejected'),
           (Image(width=320, height=240, encoding='rgb8', step=960, data=bytes(100)),
            'frame rejected: 100 bytes')]
    for k, (msg, warning) in enumerate(bad, start=1):
        msg.header.stamp.sec = k
        end = time.monotonic() + 10.0
        while warning not in vision.output() and time.monotonic() < end:
            info_pub.publish(info)
            image_pub.publish(msg)
            time.sleep(0.2)
        assert warning in vision.output(), warning
    # An unusable frame is answered with no detections, stamped with the frame's time (a
    # lock-step consumer waits for an answer to every frame).
    def answered():
        for msg, _ in bad:                  # again: the probe may have matched late
            image_pub.publish(msg)
        return {d.header.stamp.sec for _, d in detections} >= {1, 2, 3, 4}
    wait_for(answered, 10.0, period=0.2, what='answers to the rejected frames')
    assert all(d.detections == [] for _, d in detections)
    detections.clear()
    def processed():
        image_pub.publish(frame)
        return bool(detections)
    wait_for(processed, 10.0, period=0.2, what='a good frame processed')
    assert detections[-1][1].detections == [] and vision.alive()
    # A camera_info with NaN in K is refused, and the one in use kept (issue 15, finding 7: it
    # was taken, and the node went blind until a valid one came).
    nan_info = CameraInfo(width=320, height=240,
                          k=[float('nan'), 0.0, 160.0, 0.0, 290.0, 119.0, 0.0, 0.0, 1.0])

    def refused():
        info_pub.publish(nan_info)
        return 'camera_info ignored: K is not finite' in vision.output()
    wait_for(refused, 10.0, period=0.2, what='the NaN camera_info refused')
    assert 'keeping the one in use' in vision.output()


def test_the_vision_node_takes_frames_only_while_something_reads_its_output(start_node, probe):
    """Lazy (the default): the simulator renders a camera only for its readers, so frames that
    no detection is wanted from are not asked for."""
    vision = start_node('vision_node')
    wait_for(lambda: 'looking for' in vision.output(), 20.0, what='the vision node')
    image_pub = probe.node.create_publisher(Image, 'image_raw', qos_profile_sensor_data)
    for _ in range(2):
        reader = probe.node.create_subscription(MaterialDetectionArray, '/detections',
                                                lambda _msg: None, 10)
        wait_for(lambda: image_pub.get_subscription_count() == 1, 20.0,
                 what='the vision node on the camera once its detections have a reader')
        probe.node.destroy_subscription(reader)
        wait_for(lambda: image_pub.get_subscription_count() == 0, 20.0,
                 what='the vision node off the camera once the reader is gone')
    assert 'not taking camera frames' in vision.output() and vision.alive()
    eager = start_node('vision_node', '-p', 'lazy:=false', '-r', '__node:=eager_vision',
                       name='eager_vision')
    wait_for(lambda: image_pub.get_subscription_count() == 1, 20.0,
             what='a vision node with lazy:=false on the camera without readers')
    assert eager.alive()
