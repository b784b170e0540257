"""Vision-sorting node: finds the cell's materials in the belt camera's images.

Subscribes ``image_raw`` and ``camera_info`` (remap them to the camera, e.g.
``-r image_raw:=/belt_camera/image_raw``); publishes ``detections``
(sim_interfaces/MaterialDetectionArray, in the world frame) for every usable frame and an
annotated ``debug_image`` while someone subscribes. The camera's pose, the belt height and the
material size come from the world file (or from parameters).
"""
from __future__ import annotations

import statistics
import sys
import time
from collections import deque
from typing import Any, Deque, Dict, Optional, Tuple

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.subscription import Subscription
from sensor_msgs.msg import CameraInfo, Image
from sim_interfaces.msg import MaterialDetection, MaterialDetectionArray

from perception.projection import CameraModel, intrinsics_problem
from perception.segmentation import ColorClass, classes_of
from perception.tracker import Tracker
from perception.vision import MaterialVision
from ros_common.node_main import run_node
from ros_common.params import Param, declare_params
from ros_common.stamps import to_seconds
from world_description import PIPELINE_CELL
from world_description.camera_geometry import look_at_rotation
from world_description.resources import resolve_resource
from world_description.world_config import load_world

ENCODINGS = ('rgb8', 'bgr8')


PARAMS = (
    Param('world', PIPELINE_CELL, 'World file with the camera pose, the conveyor and the '
          'materials; empty: use the explicit parameters below'),
    Param('camera', 'belt_camera', 'Name of the camera in the world file'),
    Param('camera_position', [0.0], 'Optical frame position in the world [m] (without a world '
          'file)'),
    Param('camera_look_at', [0.0], 'Point the camera looks at [m] (without a world file)'),
    Param('support_height', -1.0, "Height of the surface the materials rest on [m]; -1: the "
          "world file's belt top"),
    Param('material_size', -1.0, "Edge of the cubic materials [m]; -1: the world file's"),
    Param('classes', Parameter.Type.STRING_ARRAY, 'Colour classes; each has <name>.hue_ranges, '
          '<name>.min_saturation, <name>.min_value. Unset: the world file\'s material classes'),
    Param('track_gate', 0.04, "Largest distance between a track's prediction and a new "
          'observation [m]', 1e-3, 1.0),
    Param('track_min_hits', 3, 'Frames before a material is reported', 1, 1000),
    Param('track_max_missed', 5, 'Frames without a match before a track ends', 0, 1000),
    Param('frame_id', 'world', 'Frame of the reported positions'),
    Param('lazy', True, 'Take camera frames only while something reads detections or '
          'debug_image (the simulator renders a camera only for its readers)'),
)


class VisionConfigError(ValueError):
    """Parameters the node cannot run with."""


class VisionNode(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('vision_node', **kwargs)
        p = declare_params(self, PARAMS)
        world = load_world(resolve_resource(p['world'])) if p['world'] else None
        classes = self._classes(world)
        camera_pose, support, size, yaw = self._geometry(world, p)
        self._pose, self._support, self._size, self._yaw = camera_pose, support, size, yaw
        self._classes_cfg = classes
        self._tracker = Tracker(p['track_gate'], p['track_min_hits'],
                                p['track_max_missed'])
        self._frame_id = p['frame_id']
        self._vision: Optional[MaterialVision] = None
        self._info_key: Optional[Tuple[Any, ...]] = None   # the camera_info in use
        self._latencies: Deque[float] = deque(maxlen=500)
        self._warned: Dict[str, float] = {}
        self._last_stats = time.monotonic()
        self._lazy = bool(p['lazy'])
        readers = PublisherEventCallbacks(matched=self._on_readers)
        self._pub = self.create_publisher(MaterialDetectionArray, 'detections',
                                          QoSProfile(depth=10), event_callbacks=readers)
        self._debug_pub = self.create_publisher(Image, 'debug_image', qos_profile_sensor_data,
                                                event_callbacks=readers)
        self.create_subscription(CameraInfo, 'camera_info', self._on_info,
                                 qos_profile_sensor_data)
        self._image_sub: Optional[Subscription] = None
        self._on_readers()
        self.get_logger().info(
            f'looking for {[c.name for c in classes]} materials ({size} m) on z = {support} m '
            f'through {self.resolve_topic_name("image_raw")}; detections on '
            f'{self._pub.topic_name}')

    def _on_readers(self, _matched=None) -> None:
        """Lazy: watch the camera only while the outputs have readers. Frames nobody's
        detections need cost the simulator a rendering each (a trial's coordinator stops reading
        once loading is over and the belt stands)."""
        wanted = not self._lazy or (self._pub.get_subscription_count()
                                    + self._debug_pub.get_subscription_count()) > 0
        if wanted and self._image_sub is None:
            self._image_sub = self.create_subscription(Image, 'image_raw', self._on_image,
                                                       qos_profile_sensor_data)
            if self._lazy:
                self.get_logger().info('detections have a reader: taking camera frames')
        elif not wanted and self._image_sub is not None:
            self.destroy_subscription(self._image_sub)
            self._image_sub = None
            self.get_logger().info('no reader of detections or debug_image: not taking camera '
                                   'frames until one comes (lazy:=false to take them anyway)')

    # --- configuration ------------------------------------------------------------------------
    def _classes(self, world):
        """The colour classes: the world's material classes unless ``classes`` names others
        (each with its ``<name>.hue_ranges``); ``<name>.min_saturation`` and ``min_value``
        may be set for either."""
        named = self._unset_or('classes')
        from_world = ({c.name: c for c in classes_of(world.materials)}
                      if world is not None and world.materials is not None else {})
        if not named and not from_world:
            raise VisionConfigError('no colour classes: give a world file with materials, or '
                                    'classes with <name>.hue_ranges each')
        classes = []
        for name in (named or list(from_world)):
            d = from_world.get(name)
            self.declare_parameter(f'{name}.hue_ranges', Parameter.Type.INTEGER_ARRAY,
                                   ParameterDescriptor(
                                       description=f'OpenCV hue ranges (0..180) of {name}: lo, '
                                                   'hi, lo, hi, ... (unset: the world\'s)',
                                       read_only=True))
            self.declare_parameter(f'{name}.min_saturation', 110,
                                   ParameterDescriptor(read_only=True))
            self.declare_parameter(f'{name}.min_value', 50, ParameterDescriptor(read_only=True))
            flat = self._unset_or(f'{name}.hue_ranges')
            if flat is None:
                if d is None:
                    raise VisionConfigError(f'class {name} is no material class of the world: '
                                            f'it needs {name}.hue_ranges')
                flat = [v for r in d.hue_ranges for v in r]
            flat = list(flat)
            if len(flat) < 2 or len(flat) % 2:
                raise VisionConfigError(f'{name}.hue_ranges must hold pairs lo, hi; got {flat}')
            try:
                classes.append(ColorClass(
                    name, tuple((int(flat[i]), int(flat[i + 1])) for i in range(0, len(flat), 2)),
                    int(self.get_parameter(f'{name}.min_saturation').value),
                    int(self.get_parameter(f'{name}.min_value').value),
                    size=d.size if d is not None else None))
            except ValueError as exc:
                raise VisionConfigError(str(exc)) from None
        return classes

    def _unset_or(self, name: str) -> Any:
        """A parameter declared without a default: its value, or None if none was given."""
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    def _geometry(self, world, p):
        position, look_at = list(p['camera_position']), list(p['camera_look_at'])
        support, size, yaw = p['support_height'], p['material_size'], 0.0
        if world is not None:
            cams = [c for c in world.cameras if c.name == p['camera']]
            if not cams or cams[0].position is None:
                raise VisionConfigError(f'world {p["world"]} has no fixed camera '
                                        f'"{p["camera"]}"')
            if len(position) != 3:
                position, look_at = list(cams[0].position), list(cams[0].look_at)
            if world.conveyor is not None:
                support = world.conveyor.position[2] if support < 0.0 else support
                yaw = world.conveyor.yaw
            if world.materials is not None and size <= 0.0:
                size = world.materials.size
        if len(position) != 3 or len(look_at) != 3:
            raise VisionConfigError('camera_position and camera_look_at need 3 values each '
                                    '(or a world file with the camera)')
        if support < 0.0 or size <= 0.0:
            raise VisionConfigError('support_height and material_size are needed (or a world '
                                    'file with a conveyor and materials)')
        rotation = look_at_rotation(position, look_at)
        return (np.asarray(position, float), rotation), float(support), float(size), yaw

    # --- frames -------------------------------------------------------------------------------
    def _on_info(self, msg: CameraInfo) -> None:
        key = (msg.width, msg.height, tuple(msg.k))
        if key == self._info_key:
            return
        problem = intrinsics_problem(msg.width, msg.height, msg.k)
        if problem:
            # (A NaN in K would blind the node until a valid camera_info came.)
            self.get_logger().warn(
                f'camera_info ignored: {problem}; '
                + ('keeping the one in use' if self._vision is not None else 'no frames used'),
                throttle_duration_sec=5.0)
            return
        k = np.asarray(msg.k, float).reshape(3, 3)
        position, rotation = self._pose
        camera = CameraModel(k, rotation, position)
        self._vision = MaterialVision(camera, msg.width, msg.height, self._support, self._size,
                                      self._classes_cfg, yaw=self._yaw, tracker=self._tracker)
        self._info_key = key

    def _on_image(self, msg: Image) -> None:
        frame, vision = self._frame(msg), self._vision
        if frame is None or vision is None:
            # Every frame gets an answer (a lock-step consumer waits for it): none found.
            skipped = MaterialDetectionArray()
            skipped.header.stamp = msg.header.stamp
            skipped.header.frame_id = self._frame_id
            self._pub.publish(skipped)
            return
        start = time.perf_counter()
        result = vision.process(to_seconds(msg.header.stamp), frame)
        self._pub.publish(self._detections(msg, result.tracks))
        self._latencies.append(time.perf_counter() - start)
        if self._debug_pub.get_subscription_count() > 0:
            debug = vision.annotate(frame, result)
            self._debug_pub.publish(Image(header=msg.header, height=debug.shape[0],
                                          width=debug.shape[1], encoding='rgb8',
                                          step=3 * debug.shape[1], data=debug.tobytes()))
        self._log_stats()

    def _detections(self, msg: Image, tracks) -> MaterialDetectionArray:
        """The frame's answer: every track seen so far, at the frame's stamp."""
        out = MaterialDetectionArray()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = self._frame_id
        for track in tracks:
            if track.last is None:          # (a reported track has been seen)
                continue
            d = MaterialDetection(id=track.id, color=track.color, u=track.last.u,
                                  v=track.last.v, confidence=float(track.confidence),
                                  hits=track.hits)
            d.position.x, d.position.y, d.position.z = (float(v) for v in track.position)
            d.velocity.x, d.velocity.y, d.velocity.z = (float(v) for v in track.velocity())
            out.detections.append(d)
        return out

    def _frame(self, msg: Image) -> Optional[np.ndarray]:
        """The image as an RGB array, or None (with a throttled warning) if unusable."""
        if self._vision is None:
            self._warn('info', 'no camera_info yet: frames skipped')
            return None
        if msg.encoding not in ENCODINGS:
            self._warn('encoding', f'frame with encoding "{msg.encoding}" rejected: expected '
                                   f'{ENCODINGS}')
            return None
        if msg.width == 0 or msg.height == 0 or not len(msg.data):
            self._warn('empty', 'empty frame rejected')
            return None
        if (msg.width, msg.height) != (self._vision.width, self._vision.height):
            self._warn('size', f'frame {msg.width}x{msg.height} rejected: camera_info says '
                               f'{self._vision.width}x{self._vision.height}')
            return None
        if msg.step < 3 * msg.width or len(msg.data) < msg.step * msg.height:
            self._warn('bytes', f'frame rejected: {len(msg.data)} bytes for step {msg.step} x '
                                f'{msg.height}')
            return None
        rows = np.frombuffer(msg.data, np.uint8)[:msg.step * msg.height]
        frame = rows.reshape(msg.height, msg.step)[:, :3 * msg.width].reshape(
            msg.height, msg.width, 3)
        return np.ascontiguousarray(frame[..., ::-1] if msg.encoding == 'bgr8' else frame)

    def _warn(self, reason: str, text: str) -> None:
        """At most one warning per reason every 5 s (rclpy throttles per call site only)."""
        now = time.monotonic()
        if now - self._warned.get(reason, -1e9) >= 5.0:
            self._warned[reason] = now
            self.get_logger().warn(text)

    def _log_stats(self) -> None:
        now = time.monotonic()
        if now - self._last_stats < 30.0 or not self._latencies:
            return
        self._last_stats = now
        ms = sorted(1e3 * v for v in self._latencies)
        self.get_logger().info(
            f'per-frame latency median {statistics.median(ms):.2f} ms, p99 '
            f'{ms[min(len(ms) - 1, int(0.99 * len(ms)))]:.2f} ms; materials so far: '
            f'{len(self._tracker.confirmed_ids)}')


def main(args=None) -> int:
    return run_node(VisionNode, 'vision_node', (VisionConfigError, ValueError), args=args)


if __name__ == '__main__':
    sys.exit(main())
