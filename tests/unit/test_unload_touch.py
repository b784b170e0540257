"""A youBot unload whose arm stops on its way down onto a plate material finds out why: stopped
on the material's top, over the grip (the material stands taller than it was loaded as: a
perturbed cell's edges vary by 4 %, and a 56 mm cube stopped the tool 7.6 mm up and 8.5 mm
across), it keeps the edge its fingers found and closes them there; stopped anywhere else, the
unload fails as before. (In the perturbed cell's dense sweep, one seed lost two oranges this
way at every belt speed: "the arm did not reach the material".)"""
import copy
import math

import numpy as np
import pytest
from test_cell_rules import world
from test_material_classes import PAPER_CLASSES as PAPER
from test_pipeline import _YoubotIK, observation

from cell_layout.layout import YOUBOT_CARRY_Q
from cell_layout.reach import youbot_tool_quaternion
from cell_layout.unload_geometry import YOUBOT_FK
from cell_layout.world_layout import layout_from_world
from coordinator.pipeline import Material, Pipeline, Settings
from coordinator.pipeline.model import ArmReading, Observation, TransportState

last = []           # (the observation the arm stopped at)


class Ports(_YoubotIK):
    def __init__(self) -> None:
        super().__init__()
        self.grips = []
        self.events = []

    def follow(self, robot, follower):
        return True

    def drive(self, robot, *twist):
        pass

    def trajectory(self, arm, points, start, continuing=False):
        return 0.0

    def grip(self, arm, on):
        self.grips.append(on)
        return True, ''

    def event(self, event):
        self.events.append(event)


def stopped(shift):
    """The transport on its way down onto a 50 mm orange on plate slot 2, and its arm stopped
    with the tool ``shift`` (base_link) from the grip, at the grip's tilt, once the motion's
    time and the settle margin are over."""
    layout = layout_from_world(world(copy.deepcopy(PAPER)))
    ports = Ports()
    run_ = Pipeline(layout, ports, Settings())
    tr = run_.transport
    stand = layout.stand('pool_left')
    m = Material(1, 'orange', np.zeros(3), 0.0, 3, status='on_plate', slot=2, size=0.05)
    run_.materials[1] = m
    tr.queue, tr.base.goal = [m], stand.name
    tr.state = TransportState.DRIVE
    tr._plan_unload(observation(0.0, np.zeros(6), YOUBOT_CARRY_Q, stand.pose), m)
    assert tr.state is TransportState.GRASP
    contact = tr._carry.contact
    tool = YOUBOT_FK.fk(contact)[:3, 3] + np.asarray(shift)
    q, _ = ports.solve('youbot', tool, youbot_tool_quaternion(
        tool, math.radians(tr._carry.grip_tilt)), 'base_link', contact)
    assert q is not None
    end = tr.arm.motion.end + run_.s.settle_margin + 0.1
    obs = observation(end, np.zeros(6), q, stand.pose, youbot_dq=np.zeros(5))
    last[:] = [obs]
    tr._grasp(obs)
    return tr, m, ports


@pytest.mark.parametrize('shift', [(0.0, 0.0, 0.004), (0.0, 0.0, 0.006), (0.0, 0.0, 0.012),
                                   (0.008, -0.0025, 0.0076)])
def test_an_arm_stopped_on_the_material_s_top_grips_it_there_and_keeps_its_edge(shift):
    higher = shift[2]
    tr, m, ports = stopped(shift)
    # Its fingertips (10.4 mm below the tool) on its top: at the grip they would be 2 mm over
    # the top it was loaded with, so the material is 2 mm more than the stop taller.
    assert m.size == pytest.approx(0.05 + higher + 0.002, abs=2e-4)
    assert ports.grips == [True] and tr._armed and tr.state is TransportState.GRASP
    assert m.status == 'on_plate'
    touched = [e for e in ports.events if e.kind.value == 'replanned']
    assert touched and 'higher than loaded' in touched[-1].detail
    # The gripper has not reported closing yet (its state comes a tick or two later): the
    # unload waits for it, though the arm's motion ended more than its settle margin ago.
    q = tr.arm.q(last[0])
    tr._grasp(Observation(last[0].now + 0.1, {'zu12': ArmReading(np.zeros(6)),
                                              'youbot': ArmReading(q, np.zeros(5))},
                          last[0].bases))
    assert tr.state is TransportState.GRASP and m.status == 'on_plate'
    # The gripper reports closed and holding a moment later: off the plate from there.
    later = Observation(last[0].now + 0.2, {'zu12': ArmReading(np.zeros(6)),
                                            'youbot': ArmReading(q, np.zeros(5), True, True)},
                        last[0].bases)
    tr._grasp(later)
    assert [e.kind.value for e in ports.events][-2:] == ['unload_grasped', 'state']
    assert tr.state is TransportState.CARRY


@pytest.mark.parametrize('shift', [(0.03, 0.0, 0.0), (0.0, 0.0, 0.05), (0.0, 0.02, 0.006)])
def test_an_arm_stopped_anywhere_else_fails_the_unload_as_not_reaching_the_material(shift):
    tr, m, ports = stopped(shift)
    assert m.size == 0.05 and True not in ports.grips
    failed = [e for e in ports.events if e.kind.value == 'grasp_failed']
    assert failed and failed[-1].detail == 'unload: the arm did not reach the material'
