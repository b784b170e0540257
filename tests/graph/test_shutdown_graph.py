"""Stopping a run at any moment, as ``ros2 launch`` does on Ctrl-C (SIGINT to every process of
the launch) or on SIGTERM: the processes the launch files start end by themselves, each with
exit code 0, and print no traceback and no FATAL or ERROR line. The graphs here are the launch
files' (sim_bringup/launch), started as the same executables with the same parameters."""
import random
import signal
import time

import pytest

from helpers import NodeProcess, wait_for
from studies.trial_graph import pipeline_graph

SQUARE = ', '.join(['speed 0.5, forward 5s, speed 1.0, left 7.854s'] * 4) + ', stop'
# ros2 launch's grace after SIGINT before it escalates to SIGTERM (sigterm_timeout).
GRACE_S = 5.0


def _pipeline(tmp_path):
    graph = pipeline_graph(5, 0.12, synchronous=True, record_dir=tmp_path / 'bags',
                           bag_name='run')
    return [(n.name, n.executable, n.ros_args()[1:]) for n in graph]


def _mini_demo(tmp_path):
    from world_description.resources import resolve_resource
    params = str(resolve_resource('package://sim_bringup/config/sim.yaml'))
    remaps = ['-r', 'cmd_vel:=/mini_robot/cmd_vel', '-r', 'odom:=/mini_robot/odom',
              '-r', 'cmd_vel_out:=/mini_robot/cmd_vel_out']
    return [('recorder', 'recorder', ['-p', f'output_dir:={tmp_path / "bags"}']),
            ('sim_node', 'sim_node', ['--params-file', params]),
            ('drive_check', 'drive_check', ['-p', 'use_sim_time:=true', '-p',
                                            f'script:={SQUARE}', *remaps]),
            ('teleop', 'teleop', ['-r', '__ns:=/mini_robot', '-p', 'use_sim_time:=true', '-p',
                                  f'script:={SQUARE}', '-p', 'publish_rate:=50.0', '-p',
                                  'wait_for_subscriber:=30.0'])]


def _youbot(tmp_path):
    return [('sim_node', 'sim_node', ['-p',
                                      'world:=package://world_description/worlds/youbot.yaml']),
            ('kinematics_node', 'kinematics_node', ['-r', '__ns:=/youbot']),
            ('recorder', 'recorder', ['-p', f'output_dir:={tmp_path / "bags"}'])]


GRAPHS = {'pipeline': _pipeline, 'mini_robot_demo': _mini_demo, 'youbot': _youbot}


def _clean(output: str) -> bool:
    return not any(line.startswith(('[ERROR]', '[FATAL]')) or 'Traceback' in line
                   for line in output.splitlines())


def _handles_sigterm(pid: int) -> bool:
    """Whether the process catches SIGTERM (Linux /proc): its console script's first line has
    run (ros_common/early_stop.py). Python itself catches only SIGINT."""
    try:
        status = open(f'/proc/{pid}/status').read()
    except OSError:
        return True               # (it ended: nothing to wait for)
    caught = int(status.split('SigCgt:')[1].split()[0], 16)
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def _stop_at(graph: str, sig: int, moment: float, run):
    """Start the graph's processes, send each ``sig`` ``moment`` seconds after they all handle
    it (as a terminal and ros2 launch do on Ctrl-C); those still running after twice launch's
    grace, and the exit codes. (The interpreter's own start, before that, is a known limit:
    docs/known-limits.md. On a loaded machine it takes seconds.)"""
    procs = [NodeProcess(executable, args, run, name=name)
             for name, executable, args in GRAPHS[graph](run)]
    try:
        wait_for(lambda: all(_handles_sigterm(p.proc.pid) for p in procs), 120.0,
                 what='every process past its interpreter\'s start')
        time.sleep(moment)        # (the moment of the stop: a window, not a wait)
        # Twice, as a terminal's Ctrl-C arrives: from the terminal to the process group, and
        # from ros2 launch to each process it started.
        for _ in range(2):
            for proc in procs:
                if proc.alive():
                    proc.proc.send_signal(sig)
            time.sleep(0.05)
        deadline = time.monotonic() + GRACE_S * 2
        wait_for(lambda: all(not p.alive() for p in procs) or time.monotonic() > deadline,
                 GRACE_S * 2 + 1, what='every process to end')
        return procs, [p.name for p in procs if p.alive()], {
            p.name: p.proc.returncode for p in procs}
    finally:
        for proc in procs:
            proc.stop(signal.SIGKILL, 5.0)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['sigint', 'sigterm'])
@pytest.mark.parametrize('graph', sorted(GRAPHS))
def test_a_stop_at_any_moment_ends_every_process_cleanly(graph, sig, tmp_path):
    """Two moments each: while the processes start (their imports and set-up, from their
    console script's first line) and while they run."""
    rng = random.Random(f'{graph}-{sig}')
    for moment in (rng.uniform(0.0, 1.0), rng.uniform(2.0, 10.0)):
        run = tmp_path / f'at_{moment:.1f}s'
        run.mkdir()
        procs, lingering, codes = _stop_at(graph, sig, moment, run)
        report = [line for p in procs for line in p.problems()]
        assert not lingering, (f'{graph} at {moment:.1f} s: still running {lingering}',
                               [p.output()[-2000:] for p in procs if p.name in lingering])
        assert all(code == 0 for code in codes.values()), (moment, codes, report)
        assert all(_clean(p.output()) for p in procs), (moment, report)
