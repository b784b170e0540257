"""The lock-step ordering hazard, shown directly: a command that DDS delivers after the step
request it was meant to precede. With the command announced in the request, the simulator waits
for it and the step is the same as with prompt delivery; without, the step runs without it."""
import time

import pytest

from helpers import LockStepDriver

BATCH = 48                 # steps of 1/240 s: 0.2 s of simulated time
DELAY_S = 0.5              # how late the command is delivered after the step request [wall s]


class LockStep(LockStepDriver):
    def x_at(self, stamp) -> float:
        return self.odom_at(stamp).pose.pose.position.x

    def batch(self, commands: int, late: bool) -> float:
        """x travelled in one batch whose forward command arrives before or after the step
        request; the robot starts at rest."""
        start = self.reply(self.step(1)).sim_time
        x0 = self.x_at(start)
        if not late:
            self.send(0.15)
            future = self.step(BATCH, commands)
        else:
            future = self.step(BATCH, commands)
            time.sleep(DELAY_S)                # the delivery delay being simulated
            if commands:
                # Answered without stepping: the announced command is not in yet.
                early = self.reply(future, timeout=0.0)
                assert not early.success and early.commands_pending, early.message
                assert early.sim_time == start, 'the step ran before its command arrived'
                future.send()
            self.send(0.15)
        reply = self.reply(future)
        assert reply.success, reply.message
        return self.x_at(reply.sim_time) - x0


@pytest.fixture
def fresh_sim(start_node, probe):
    """A new lock-step simulator for each measurement: every batch starts from the same state."""
    running = []

    def start():
        for proc in running:
            proc.stop()
        running.append(start_node('sim_node', '-p', 'synchronous:=true', '-p',
                                  'state_publish_rate:=240.0'))
        return LockStep(probe)
    return start


def test_a_late_command_announced_with_its_step_acts_as_if_it_were_prompt(fresh_sim):
    prompt = fresh_sim().batch(commands=1, late=False)
    late = fresh_sim().batch(commands=1, late=True)
    assert prompt > 0.005                    # it drove during the batch
    assert late == prompt                    # bit for bit: the same steps with the same inputs


def test_a_late_command_not_announced_misses_its_step(fresh_sim):
    # The hazard the protocol removes: the batch ran before the command was there.
    late = fresh_sim().batch(commands=0, late=True)
    assert abs(late) < 1e-4


def test_a_step_whose_commands_are_missing_is_answered_pending_not_run(fresh_sim):
    lockstep = fresh_sim()
    before = lockstep.reply(lockstep.step(1))
    lockstep.send(0.0)
    pending = lockstep.step(BATCH, commands=2)
    reply = lockstep.reply(pending, timeout=2.0)            # asked again for two seconds
    assert not reply.success and reply.commands_pending
    assert '1 of the 2 commands' in reply.message
    assert pending.pending_replies > 1
    assert reply.step_count == before.step_count           # nothing ran
    lockstep.send(0.0)                                      # the second one comes after all
    assert lockstep.reply(pending).success
