"""Counting what a node refused of its inputs, for /diagnostics."""
from ros_common.input_report import OK, WARN, InputReport


def test_each_input_is_counted_by_kind_and_warns_until_a_quiet_report():
    report = InputReport()
    assert not report and report.statuses() == []
    report.add('youbot', 'cmd_vel', 'non-finite', 'youbot/cmd_vel rejected: NaN')
    report.add('youbot', 'cmd_vel', 'clamped', 'youbot/cmd_vel clamped')
    report.add('youbot', 'cmd_vel', 'clamped', 'youbot/cmd_vel clamped again')
    report.add('zu12', 'arm_controller/joint_trajectory', 'rejected', 'point 0: ...')
    first = {s.name: s for s in report.statuses()}
    assert set(first) == {'youbot/cmd_vel', 'zu12/arm_controller/joint_trajectory'}
    cmd = first['youbot/cmd_vel']
    assert cmd.level == WARN and cmd.hardware_id == 'youbot'
    assert cmd.message == ('3 refused or changed since the last report: '
                           'youbot/cmd_vel clamped again')
    assert dict(cmd.values) == {'clamped': '2', 'non-finite': '1',
                                'last reason': 'youbot/cmd_vel clamped again'}
    quiet = {s.name: s for s in report.statuses()}
    assert quiet['youbot/cmd_vel'].level == OK
    assert '(3 in all)' in quiet['youbot/cmd_vel'].message
