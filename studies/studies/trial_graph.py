"""The node graph of a pipeline run, described once (no ROS): which executables run, in which
namespaces, with which parameters and remappings.

The trial runner (``trials.py``) starts these processes, the launch file
(``sim_bringup/launch/pipeline.launch.py``) turns them into launch_ros ``Node`` actions, and
``run_trials --show-graph`` prints them as command lines.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple, Union

import yaml

from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world

# The coordinator's decisions per simulated second; in lock-step also the simulator's state
# and /clock rates (each /clock message costs every node with sim time about a millisecond).
CONTROL_RATE = 30.0
# The physics step: PyBullet's default. Trials may take 1/120 s (run_trials --time-step):
# docs/benchmarks.md compares the two.
TIME_STEP = 1.0 / 240.0


def tick_rate(time_step: float) -> float:
    """The control rate on whole physics steps, as the simulator counts time (whole
    nanoseconds per step): at 1/120 s, 30 Hz is 4 steps of 8333333 ns, 33333332 ns, and states
    published every 33333333 ns would fall a step late. At 1/240 s, 8 steps: 29.9999973 Hz."""
    dt_ns = round(time_step * 1e9)
    steps = max(1, round(1e9 / CONTROL_RATE / dt_ns))
    return 1e9 / (steps * dt_ns)
# Camera frames (and the debug image, published only for subscribers) stay out of a recorded
# bag: 15 Hz of 230 kB frames would make it about 500 MB per run.
UNRECORDED_TOPICS = ('/belt_camera/image_raw', '/debug_image')

ParameterValue = Union[bool, int, float, str, List[str]]


@dataclass(frozen=True)
class GraphNode:
    """One process of the graph."""
    name: str                           # what the run calls it (its log file's name)
    package: str
    executable: str
    namespace: str = ''
    parameters: Dict[str, ParameterValue] = field(default_factory=dict)
    remappings: Tuple[Tuple[str, str], ...] = ()

    def ros_args(self) -> List[str]:
        """The node's arguments as ``ros2 run`` takes them after the executable."""
        args = ['--ros-args']
        if self.namespace:
            args += ['-r', f'__ns:=/{self.namespace}']
        for source, target in self.remappings:
            args += ['-r', f'{source}:={target}']
        for name, value in self.parameters.items():
            args += ['-p', f'{name}:={parameter_text(value)}']
        return args

    def command(self) -> List[str]:
        """The command line with the executable found on PATH (scripts/env.sh puts each
        package's lib/<package> there, where ``ros2 run`` looks)."""
        return [self.executable, *self.ros_args()]


def parameter_text(value: ParameterValue) -> str:
    """A parameter value as ``-p name:=value`` takes it (YAML): a string that YAML would read
    as something else (empty, a number, true) is quoted."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, list):       # (each item YAML-quoted: any text goes through)
        return '[' + ', '.join("'" + str(v).replace("'", "''") + "'" for v in value) + ']'
    if isinstance(value, str):
        try:
            plain = yaml.safe_load(value) == value
        except yaml.YAMLError:
            plain = False
        return value if plain and value.strip() == value else "'" + value.replace("'", "''") + "'"
    return str(value)


def _sim_parameters(seed: int, belt_speed: float, synchronous: bool, world: str, rate: float,
                    time_step: float, real_time_factor: Optional[float]
                    ) -> Dict[str, ParameterValue]:
    sim: Dict[str, ParameterValue] = {
        'world': world, 'synchronous': synchronous, 'state_publish_rate': rate,
        'time_step': time_step,
        # Lock-step: /clock at the control rate; real time: at every physics step.
        'clock_publish_rate': rate if synchronous else 0.0,
        'scenario_seed': seed,
        # Lock-step: the belt runs from the first step (nothing moves before the coordinator
        # steps). Real time: it stands until the coordinator starts it, once the vision node
        # and the kinematics services are up; started with the simulator, it would carry
        # materials past a camera nobody watches yet.
        'belt_speed': belt_speed if synchronous else 0.0}
    # (The bases' speed limits come from the world file's drive sections.)
    if real_time_factor is not None:
        sim['real_time_factor'] = real_time_factor
    return sim


def pipeline_graph(seed: int, belt_speed: float, synchronous: bool = True,
                   world: str = PIPELINE_CELL, real_time_factor: Optional[float] = None,
                   result_file: Optional[Path] = None, progress_file: Optional[Path] = None,
                   record_dir: Optional[Path] = None, bag_name: Optional[str] = 'bag',
                   time_step: float = TIME_STEP,
                   recorder_ready: Optional[Path] = None,
                   bag_metadata: Optional[Dict[str, str]] = None) -> List[GraphNode]:
    """The processes of one run of the pipeline scenario, in their start order (the recorder,
    when there is one, first: it must hear the first /clock). A recording goes into
    ``record_dir``/``bag_name`` (without a name, one with the date and time);
    ``recorder_ready``: the file the recorder writes once it records /clock; ``bag_metadata``:
    the bag's custom data (what ran: studies.recorded)."""
    sim_time = {'use_sim_time': True}
    rate = tick_rate(time_step) if synchronous else CONTROL_RATE
    sim = _sim_parameters(seed, belt_speed, synchronous, world, rate, time_step,
                          real_time_factor)
    # (Lock-step: the coordinator's time is the simulator's step count; it takes no /clock.)
    coordinator: Dict[str, ParameterValue] = {
        **({} if synchronous else sim_time), 'synchronous': synchronous,
        'control_rate': CONTROL_RATE,
        'time_step': time_step, 'state_publish_rate': rate,
        'belt_speed': belt_speed, 'scenario_seed': seed, 'world': world}
    if result_file is not None:
        coordinator['result_file'] = str(result_file)
    if progress_file is not None:
        coordinator['progress_file'] = str(progress_file)
    # The IK servers name their frames as the simulator does (the world's frame prefixes).
    loaded = load_world(resolve_resource(world))
    roles = loaded.roles
    prefixes = {robot.name: robot.frame_prefix for robot in loaded.robots}
    spaces = {robot.name: robot.namespace for robot in loaded.robots}
    loader = roles.loader
    nodes = []
    if record_dir is not None:
        recorder: Dict[str, ParameterValue] = {
            **sim_time, 'output_dir': str(record_dir), 'exclude': list(UNRECORDED_TOPICS)}
        if bag_name:
            recorder['bag_name'] = bag_name
        if recorder_ready is not None:
            recorder['ready_file'] = str(recorder_ready)
        if bag_metadata:
            recorder['custom_data'] = [f'{k}={v}' for k, v in bag_metadata.items()]
        nodes.append(GraphNode('recorder', 'recording', 'recorder', parameters=recorder))
    nodes += [
        GraphNode('sim_node', 'sim_bridge', 'sim_node', parameters=sim),
        # (The vision node and the IK servers read no clock: detections carry their frame's
        # stamp, a motion an IK server sends starts when the controller takes it, and a pose it
        # publishes carries its joint state's stamp. Without use_sim_time they take no /clock,
        # which costs each node about a millisecond of CPU per message.)
        # (The world's camera, belt and material classes: a cell's own, not the paper's.)
        GraphNode('vision_node', 'perception', 'vision_node', parameters={'world': world},
                  remappings=(('image_raw', '/belt_camera/image_raw'),
                              ('camera_info', '/belt_camera/camera_info'))),
        # (The coordinator seeds every IK request with the arm's state and executes none: the
        # IK servers need no joint_states, 30 messages a second each.)
        # (One IK server per arm, in its robot's namespace; ``arm`` is its robot in the world,
        # whose entry gives its model.)
        *(GraphNode(f'{arm}_kinematics', 'arm_kinematics', 'kinematics_node',
                    namespace=spaces.get(arm, arm),
                    parameters={'world': world, 'arm': arm,
                                'frame_prefix': prefixes.get(arm, ''),
                                'track_joint_states': False})
          for arm in (loader, *roles.transports)),
        GraphNode('coordinator_node', 'coordinator', 'coordinator_node',
                  parameters=coordinator),
    ]
    return nodes
