"""Teleop key handling and the timed-script parser."""
import pytest

from teleop.teleop_core import TeleopError, TeleopState, parse_script


def test_report_buttons_at_the_default_speed_level():
    state = TeleopState(max_speed=0.2, max_turn=0.2)
    assert state.twist() == (0.0, 0.0, 0.0)
    assert state.press('i') == 'forward' and state.twist() == pytest.approx((0.1, 0.0, 0.0))
    state.press(',')
    assert state.twist() == pytest.approx((-0.1, 0.0, 0.0))
    state.press('j')
    assert state.twist() == pytest.approx((0.0, 0.0, 0.1))
    state.press('l')
    assert state.twist() == pytest.approx((0.0, 0.0, -0.1))
    state.press('k')
    assert state.twist() == (0.0, 0.0, 0.0)


def test_speed_keys_step_and_saturate():
    state = TeleopState(0.2, 0.2)
    state.press('w')
    for _ in range(10):
        state.press('+')
    assert state.speed_fraction == 1.0 and state.twist() == pytest.approx((0.2, 0.0, 0.0))
    for _ in range(20):
        state.press('-')
    assert state.speed_fraction == 0.0 and state.twist() == (0.0, 0.0, 0.0)


def test_unknown_key_changes_nothing():
    state = TeleopState(0.2, 0.2)
    state.press('w')
    assert state.press('?') is None
    assert state.motion == 'forward'


def test_script_parses_motions_speed_and_twist():
    script = parse_script('forward 2s, left 1.5s; speed 1.0\nbackward 500ms, twist 0.05 -0.1 1,'
                          ' stop', 0.2, 0.2)
    steps = [(s.name, s.v, s.w, s.duration) for s in script.steps]
    assert steps == [('forward', 0.1, 0.0, 2.0), ('left', 0.0, 0.1, 1.5),
                     ('backward', -0.2, 0.0, 0.5), ('twist', 0.05, -0.1, 1.0),
                     ('stop', 0.0, 0.0, 0.0)]
    assert script.duration == pytest.approx(5.0)
    assert script.command_at(0.0).name == 'forward'
    assert script.command_at(2.0).name == 'left'
    assert script.command_at(4.9).name == 'twist'
    assert script.command_at(5.0) is None


@pytest.mark.parametrize('text, fragment', [
    ('', 'empty'),
    ('forward', 'needs a duration'),
    ('jump 2s', 'unknown command'),
    ('forward two', 'bad duration'),
    ('speed 1.5', 'within 0..1'),
    ('twist 0.1 nan 2s', 'finite'),
    ('forward -2s', 'bad duration'),
])
def test_bad_scripts_name_the_statement(text, fragment):
    with pytest.raises(TeleopError, match=fragment):
        parse_script(text, 0.2, 0.2)


def test_bad_limits_raise():
    with pytest.raises(TeleopError):
        TeleopState(0.0, 0.2)


def test_holonomic_strafe_keys():
    state = TeleopState(0.2, 0.2, holonomic=True)
    assert state.press('J') == 'strafe_left' and state.twist() == pytest.approx((0.0, 0.1, 0.0))
    assert state.press('e') == 'strafe_right'
    assert state.twist() == pytest.approx((0.0, -0.1, 0.0))
    plain = TeleopState(0.2, 0.2)
    assert plain.press('J') is None and plain.motion == 'stop'


def test_holonomic_script_statements():
    script = parse_script('strafe_left 1s, strafe_right 500ms, forward 1s', 0.2, 0.2,
                          holonomic=True)
    assert [(s.name, s.v, s.vy, s.w) for s in script.steps] == [
        ('strafe_left', 0.0, 0.1, 0.0), ('strafe_right', 0.0, -0.1, 0.0),
        ('forward', 0.1, 0.0, 0.0)]
    with pytest.raises(TeleopError, match='holonomic'):
        parse_script('strafe_left 1s', 0.2, 0.2)
