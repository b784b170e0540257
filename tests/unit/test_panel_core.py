"""The control panel's logic without ROS or a browser: the robots of a world, what a page may
send, and the dead-man rule."""
import json
import math

import pytest

from teleop.panel_core import (
    DeadMan,
    Outbox,
    PanelInputError,
    parse_command,
    robots_of_world,
)
from world_description import PIPELINE_CELL
from world_description.resources import resolve_resource
from world_description.world_config import load_world


def world(name):
    return load_world(resolve_resource(f'package://world_description/worlds/{name}.yaml'))


def mini():
    return robots_of_world(world('mini_robot'), 0.2, 0.2)[0]


def test_the_robots_of_each_world():
    (robot,) = robots_of_world(world('mini_robot'), 0.2, 0.3)
    assert (robot.namespace, robot.holonomic, robot.max_speed, robot.max_turn) == \
        ('/mini_robot', False, 0.2, 0.3)
    assert robot.wheel_separation == pytest.approx(0.113)
    assert robot.camera == '/mini_robot/camera/image_raw'
    assert robot.cmd_vel == '/mini_robot/cmd_vel' and robot.odom == '/mini_robot/odom'
    (youbot,) = robots_of_world(world('youbot'), 0.2, 0.2)
    assert youbot.holonomic and youbot.wheel_separation is None
    assert not youbot.describe()['report_turns']
    cell = robots_of_world(load_world(resolve_resource(PIPELINE_CELL)), 0.8, 1.5)
    # The Zu 12 has no base: only the youBot is driven; it carries no camera, so the belt's.
    assert [r.namespace for r in cell] == ['/youbot']
    assert cell[0].camera == '/belt_camera/image_raw'
    # A fleet: the page lists every youBot, each driven on its own topics.
    fleet = robots_of_world(world('cell_two_youbots'), 0.8, 1.5)
    assert [(r.name, r.cmd_vel, r.odom) for r in fleet] == [
        ('youbot', '/youbot/cmd_vel', '/youbot/odom'),
        ('youbot2', '/youbot2/cmd_vel', '/youbot2/odom')]


@pytest.mark.parametrize('message, why', [
    (b'{"op": "stop"}', 'JSON text'),
    ('{not json', 'not JSON'),
    ('[1, 2]', 'expected'),
    ('{"op": "launch"}', 'expected'),
    ('{"op": "hold", "motion": "fly"}', 'unknown motion'),
    ('{"op": "hold", "motion": "stop"}', 'unknown motion'),
    ('{"op": "hold"}', 'unknown motion'),
    ('{"op": "speed", "fraction": 1.5}', 'within 0..1'),
    ('{"op": "speed", "fraction": NaN}', 'within 0..1'),
    ('{"op": "speed", "fraction": true}', 'within 0..1'),
    ('{"op": "speed", "fraction": "0.5"}', 'within 0..1'),
    ('{"op": "select", "namespace": 3}', 'namespace'),
    ('{"op": "stop", "pad": "' + 'x' * 5000 + '"}', 'at most'),
    # (Each of these cut the connection with a traceback and close 1011.)
    ('{"op": "hold", "motion": ["forward"]}', 'unknown motion'),
    ('{"op": "hold", "motion": {"a": 1}}', 'unknown motion'),
    ('{"op": "speed", "fraction": ' + '9' * 4000 + '}', '4000 digits'),
    ('[' * 2040 + ']' * 2040, 'not JSON: nested too deeply'),
    ('{"op": ["stop"]}', 'expected'),
    ('{"op": "report_turns", "on": "yes"}', 'true or false'),
    ('{"op": "select", "namespace": "' + 'y' * 300 + '"}', 'at most 256'),
])
def test_what_a_page_may_not_send_is_refused_with_the_reason(message, why):
    with pytest.raises(PanelInputError, match=why):
        parse_command(message)


def test_what_a_page_may_send():
    assert parse_command('{"op": "hold", "motion": "forward"}').motion == 'forward'
    assert parse_command(json.dumps({'op': 'speed', 'fraction': 0})).fraction == 0.0
    assert parse_command('{"op": "select", "namespace": "/youbot"}').namespace == '/youbot'
    assert parse_command('{"op": "report_turns", "on": true}').on
    assert parse_command('{"op": "release"}').op == 'release'


def test_a_held_button_drives_at_the_sliders_fraction_until_released():
    drive = DeadMan(mini(), 0.3)
    assert drive.tick(0.0) is None                          # nothing held: nothing sent
    drive.hold('forward', page=1, now=0.0)
    assert drive.tick(0.05) == pytest.approx((0.1, 0.0, 0.0))    # 50 % of 0.2 m/s
    drive.set_speed(1.0)
    assert drive.tick(0.1) == pytest.approx((0.2, 0.0, 0.0))
    drive.hold('left', page=1, now=0.15)
    assert drive.tick(0.2) == pytest.approx((0.0, 0.0, 0.2))      # 100 % of max_turn
    drive.release(1)
    assert drive.tick(0.25) == (0.0, 0.0, 0.0)              # one zero twist ...
    assert drive.tick(0.3) is None                          # ... then silence
    assert drive.stops == ['released']


def test_the_dead_man_stops_a_page_that_goes_silent_or_away():
    drive = DeadMan(mini(), 0.3)
    drive.hold('forward', page=1, now=0.0)
    drive.hold('forward', page=1, now=0.25)                 # the page's repeat
    assert drive.tick(0.5) is not None and drive.tick(0.5) != (0.0, 0.0, 0.0)
    assert drive.tick(0.56) == (0.0, 0.0, 0.0)              # 0.31 s without a word
    assert drive.stops == ['no word from the page for 0.3 s']
    drive.hold('backward', page=2, now=1.0)
    drive.gone(1)                                           # another page leaving: no effect
    assert drive.tick(1.1) == pytest.approx((-0.1, 0.0, 0.0))
    drive.release(1)                                        # nor its release
    assert drive.motion == 'backward'
    drive.gone(2)
    assert drive.tick(1.2) == (0.0, 0.0, 0.0)
    assert drive.stops[-1] == 'the page went away'


def test_stop_from_any_page_stops():
    drive = DeadMan(mini(), 0.3)
    drive.hold('right', page=1, now=0.0)
    drive.stop('stop pressed')
    assert drive.tick(0.1) == (0.0, 0.0, 0.0)


def test_the_reports_turn_buttons_run_the_wheels_at_half_max_speed_over_r():
    drive = DeadMan(mini(), 0.3, report_turns=True)
    drive.hold('left', page=1, now=0.0)
    _, _, wz = drive.tick(0.0)
    # Each wheel at 0.5 * 0.2 / r: wz = 2 * 0.5 * 0.2 / 0.113 = 1.77 rad/s (the report).
    assert wz == pytest.approx(1.7699, abs=1e-4)
    r, b = 0.03, 0.113
    assert (wz * b / 2) / r == pytest.approx(0.5 * 0.2 / r)
    drive.hold('right', page=1, now=0.0)
    assert drive.tick(0.0)[2] == pytest.approx(-wz)
    drive.hold('forward', page=1, now=0.0)                  # (straight motions unchanged)
    assert drive.tick(0.0) == pytest.approx((0.1, 0.0, 0.0))


def test_strafing_only_on_a_holonomic_base():
    with pytest.raises(PanelInputError, match='holonomic'):
        DeadMan(mini(), 0.3).hold('strafe_left', page=1, now=0.0)
    youbot = robots_of_world(world('youbot'), 0.2, 0.2)[0]
    drive = DeadMan(youbot, 0.3, report_turns=True)
    assert not drive.report_turns                           # (no wheel separation)
    drive.hold('strafe_left', page=1, now=0.0)
    assert drive.tick(0.0) == pytest.approx((0.0, 0.5 * youbot.max_speed, 0.0))


def test_a_bad_deadman_timeout_is_refused():
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(PanelInputError):
            DeadMan(mini(), bad)


def test_a_page_that_does_not_read_is_owed_a_bounded_outbox():
    """However much news a page is sent and however many messages of its are refused, what
    the panel keeps for it is the latest of each kind and the last few refusals."""
    box = Outbox()
    assert not box and box.take() is None
    for k in range(10000):
        box.put('state', f'{{"op": "state", "k": {k}}}')
        box.put('frame', bytes(100))
        box.refuse(f'refusal {k}')
    box.put('hello', '{"op": "hello"}')
    sent = []
    while box:
        sent.append(box.take())
    # The refusals first (the last 8), then the latest hello, state and frame.
    assert [json.loads(m)['text'] for m in sent[:8]] == [f'refusal {k}' for k in
                                                        range(9992, 10000)]
    assert sent[8:] == ['{"op": "hello"}', '{"op": "state", "k": 9999}', bytes(100)]
    assert box.dropped == 2 * 9999 + 9992
    with pytest.raises(ValueError):
        box.put('anything', '')
