"""The pipeline run as an explicit state machine (no ROS): sorting, delivery and transport.

Two machines share one clock. The loader (the paper's Zu 12, or any arm) watches the vision's
detections, picks each material off the running belt with the suction cup, sets the ones its
class's rule has it place down on their destination's next free slot, and loads the ones the
youBot carries onto its plate. The transport (the youBot) waits for its load, drives along
Bezier paths with a PD follower, unloads with its arm (into the pool from over its wall, onto
any other destination's next free slot) and drives home. Both arms end at their start poses.
Which class goes where is the world file's (cell_layout.layout's rules): no class is named
here.

The machine acts through ``Ports`` (IK, trajectories, suction, belt, base twist, events) and
sees the world through ``Observation``; the node implements both over ROS, tests fake them.
Every state has a deadline; a missed grasp is retried, then reported; a material that goes off
the belt end is reported; a port that stops answering (``NodeTimeout``) ends the run. The run
always ends with a ``RunResult``.
"""
from cell_layout.layout import YOUBOT_CARRY_Q
from cell_layout.reach import youbot_tool_quaternion
from cell_layout.unload_geometry import YOUBOT_GRASP_STANDOFF_M, clear_of_the_plate
from coordinator.pipeline.core import Pipeline
from coordinator.pipeline.loader import Loader
from coordinator.pipeline.model import (
    ArmReading,
    BaseReading,
    Detection,
    LoaderState,
    Material,
    MaterialStatus,
    Motion,
    NodeTimeout,
    Observation,
    Points,
    Ports,
    Settings,
    Tally,
    TransportState,
    known,
)
from coordinator.pipeline.transport import Transport
from trial_record.events import Event, EventKind, RunResult

__all__ = ['ArmReading', 'BaseReading', 'Detection', 'Event', 'EventKind', 'Loader',
           'LoaderState', 'Material', 'MaterialStatus', 'Motion', 'NodeTimeout', 'Observation',
           'Pipeline', 'Points', 'Ports', 'RunResult', 'Settings', 'Tally', 'Transport',
           'TransportState', 'YOUBOT_CARRY_Q', 'YOUBOT_GRASP_STANDOFF_M', 'clear_of_the_plate',
           'known', 'youbot_tool_quaternion']
