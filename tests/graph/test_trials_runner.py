"""run_trials as a user runs it, stopped while it sets a trial up and raced by a second
runner into the same directory: it ends within seconds, with a valid CSV, its campaign file
intact, and no process of its trial left."""
import csv
import json
import os
import shutil
import signal
import subprocess
import time

from helpers import wait_for
from studies.recorded import result_from_bag


def _session_processes(sid: int):
    """(pid, command) of the processes still in a session."""
    out = subprocess.run(['ps', '-eo', 'sid=,pid=,args='], capture_output=True, text=True)
    found = []
    for line in out.stdout.splitlines():
        parts = line.split(None, 2)
        if len(parts) == 3 and int(parts[0]) == sid:
            found.append((int(parts[1]), parts[2]))
    return found


def test_a_signal_while_a_trial_is_set_up_ends_the_campaign_at_once(tmp_path):
    """SIGTERM 3 s into a trial's set-up: the trial was launched anyway and ran to the end, the
    runner exited 66 s after the signal and printed "0 finished" while the trial's result said
    completed. A second run_trials into the same --out exited 0 too, and the two lost each
    other's results."""
    out = tmp_path / 'campaign'
    runner = subprocess.Popen([shutil.which('run_trials'), '--trials', '1', '--out', str(out),
                               '--progress-period', '1'], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        # Set-up under way: the simulator has started, the other nodes are starting.
        wait_for(lambda: (out / 'trial_000' / 'sim_node.log').exists()
                 or runner.poll() is not None, 60.0, what='the trial to be set up')
        assert runner.poll() is None
        second = subprocess.run([shutil.which('run_trials'), '--trials', '2', '--out',
                                 str(out)], capture_output=True, text=True, timeout=60)
        assert second.returncode == 2
        assert f'in use by another run_trials (pid {runner.pid})' in second.stderr
        assert 'Traceback' not in second.stderr
        runner.send_signal(signal.SIGTERM)
        signalled = time.monotonic()
        output, _ = runner.communicate(timeout=60)
        took = time.monotonic() - signalled
    finally:
        if runner.poll() is None:
            os.killpg(runner.pid, signal.SIGKILL)
            runner.wait()
    assert runner.returncode == 130, output
    assert took < 15.0, (took, output)           # (a few seconds; the trial takes minutes)
    assert 'interrupted' in output and 'Traceback' not in output
    with open(out / 'trials.csv') as f:
        rows = list(csv.DictReader(f))
    result = out / 'trial_000' / 'result.json'
    # The CSV says what the trial's directory says: it was stopped, or (if it had finished
    # first) its result is in both.
    status = json.loads(result.read_text())['status'] if result.exists() else None
    if rows:
        assert [row['status'] for row in rows] == [status]
    else:
        assert status in (None, 'interrupted')
    assert json.loads((out / 'campaign.json').read_text())['plan']['trials'] == 1
    wait_for(lambda: not _session_processes(runner.pid), 10.0,
             what='no process of the campaign left')


def test_a_campaign_stopped_mid_trial_keeps_the_trials_bag_whole(tmp_path):
    """SIGTERM (as `docker stop` sends it) while a recorded trial runs: the runner stopped its
    trial's processes with SIGKILL, and the bag was cut without its summary (unreadable by
    `mcap info`). Now each node is stopped with SIGINT first: the recorder closes its bag, the
    trial reads 'interrupted', no node leaves a traceback, and --resume can run it again."""
    from mcap.reader import make_reader

    out = tmp_path / 'campaign'
    runner = subprocess.Popen([shutil.which('run_trials'), '--trials', '1', '--record',
                               '--out', str(out), '--progress-period', '1'],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              start_new_session=True)
    progress = out / 'trial_000' / 'progress.json'

    def sim_time() -> float:
        try:
            return float(json.loads(progress.read_text()).get('sim_time', 0.0))
        except (OSError, ValueError, AttributeError):
            return 0.0
    try:
        # (And the recorder records the coordinator's events: on a busy machine it found their
        # topic after 3 s of simulated time, and the bag stopped then had none.)
        recorder_log = out / 'trial_000' / 'recorder.log'

        def recording_events() -> bool:
            try:
                return 'recording /coordinator_node/events' in recorder_log.read_text()
            except OSError:
                return False
        wait_for(lambda: (sim_time() >= 3.0 and recording_events()) or runner.poll() is not None,
                 180.0, what='the trial to run 3 s of simulated time, its events recorded')
        assert runner.poll() is None
        runner.send_signal(signal.SIGTERM)
        output, _ = runner.communicate(timeout=60)
    finally:
        if runner.poll() is None:
            os.killpg(runner.pid, signal.SIGKILL)
            runner.wait()
    assert runner.returncode == 130, output
    assert 'no report (no trial finished)' in output and 'Traceback' not in output
    trial = out / 'trial_000'
    assert json.loads((trial / 'result.json').read_text())['status'] == 'interrupted'
    with open(trial / 'bag' / 'bag.mcap', 'rb') as f:
        summary = make_reader(f).get_summary()         # (None, or an error, for a cut bag)
    assert summary is not None and summary.statistics.message_count > 0
    topics = {channel.topic for channel in summary.channels.values()}
    assert {'/clock', '/cell/materials', '/coordinator_node/events'} <= topics, topics
    # Its first events too (the belt started at 0.03 s), though the recorder found the topic
    # later: the coordinator keeps them for late joiners.
    from mcap_ros2.decoder import DecoderFactory
    with open(trial / 'bag' / 'bag.mcap', 'rb') as f:
        kinds = [m.kind for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()])
                 .iter_decoded_messages(topics=['/coordinator_node/events'])]
    assert 'belt_started' in kinds, kinds[:5]
    # The bag alone says what ran: it reads as the interrupted trial, and is drawn.
    kept = result_from_bag(trial / 'bag')
    assert kept.status == 'interrupted' and kept.scenario['world_data']['robots'], kept.message
    drawn = subprocess.run([shutil.which('storyboard'), str(trial / 'bag'), '-o',
                            str(tmp_path / 'board.png')], capture_output=True, text=True,
                           timeout=120)
    assert drawn.returncode == 0 and (tmp_path / 'board.png').is_file(), drawn.stderr
    for log in trial.glob('*.log'):
        text = log.read_text()
        assert 'Traceback' not in text and '[FATAL]' not in text, (log.name, text[-2000:])
    wait_for(lambda: not _session_processes(runner.pid), 10.0,
             what='no process of the campaign left')


def test_a_trial_past_its_wall_timeout_says_so(tmp_path):
    """A trial the machine runs too slowly is stopped at its wall timeout, and its record says
    that, and how far it got (it said only "no result (coordinator exit 0)": the coordinator,
    stopped, exits cleanly); the campaign goes on, and no process of the trial is left."""
    out = tmp_path / 'campaign'
    run = subprocess.run([shutil.which('run_trials'), '--trials', '1', '--seed0', '7',
                          '--wall-timeout', '8', '--out', str(out), '--bar', 'off'],
                         capture_output=True, text=True, start_new_session=True, timeout=600)
    assert 'Traceback' not in run.stdout + run.stderr
    result = json.loads((out / 'trial_000' / 'result.json').read_text())
    assert result['status'] == 'error'
    assert result['message'].startswith('stopped at its wall timeout (8 s of wall time)'), \
        result['message']
    assert '--wall-timeout' in result['message']
    rows = list(csv.DictReader((out / 'trials.csv').open()))
    assert [r['status'] for r in rows] == ['error']
