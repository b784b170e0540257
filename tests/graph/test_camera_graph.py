"""The simulated camera as ROS users expect it: reliable by default (RViz and rqt ask for
reliable), best-effort on request, and image_transport's compressed topic."""
from __future__ import annotations

import cv2
import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CompressedImage, Image

from helpers import wait_for

RAW = '/mini_robot/camera/image_raw'
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def _pixels(msg: Image) -> np.ndarray:
    return np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.width, 3)


def test_a_reliable_reader_gets_frames_and_jpeg_follows_the_raw_image(start_node, probe):
    raw = probe.collect(Image, RAW, RELIABLE)
    jpeg = probe.collect(CompressedImage, RAW + '/compressed', RELIABLE)
    start_node('sim_node', '-p', 'real_time_factor:=2.0')
    wait_for(lambda: len(raw) >= 5 and len(jpeg) >= 5, 30.0, what='raw and JPEG frames')
    (info,) = probe.node.get_publishers_info_by_topic(RAW)
    assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    stamps = {(m.header.stamp.sec, m.header.stamp.nanosec): m for _, m in raw}
    pairs = [(stamps[key], m) for _, m in jpeg
             if (key := (m.header.stamp.sec, m.header.stamp.nanosec)) in stamps]
    assert pairs, 'no JPEG frame with the stamp of a raw one'
    image, compressed = pairs[-1]
    assert compressed.format == 'rgb8; jpeg compressed bgr8'
    assert compressed.header.frame_id == image.header.frame_id == 'camera_optical_frame'
    decoded = cv2.imdecode(np.frombuffer(compressed.data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (240, 320, 3)
    rgb = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB).astype(float)
    assert np.abs(rgb - _pixels(image)).mean() < 4.0       # JPEG at quality 90
    assert len(compressed.data) < len(image.data) / 4


def test_best_effort_on_request_and_a_sensor_data_reader_gets_it(start_node, probe):
    frames = probe.collect(Image, RAW, qos_profile_sensor_data)
    start_node('sim_node', '-p', 'real_time_factor:=2.0', '-p',
               'camera_reliability:=best_effort')
    wait_for(lambda: len(frames) >= 3, 30.0, what='best-effort frames')
    (info,) = probe.node.get_publishers_info_by_topic(RAW)
    assert info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert _pixels(frames[-1][1]).std() > 5


def test_an_unknown_reliability_is_refused_at_start(start_node):
    sim = start_node('sim_node', '-p', 'camera_reliability:=sometimes')
    wait_for(lambda: not sim.alive(), 30.0, what='sim_node to exit')
    assert sim.proc.returncode == 1
    assert 'camera_reliability must be one of reliable, best_effort' in sim.output()
