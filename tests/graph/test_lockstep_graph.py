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
    # Asked again until the first command is in (DDS may deliver it after the request: the
    # answer then says 0 of 2), and once more: still pending, nothing run.
    reply = lockstep.ask_until(pending, lambda r: '1 of the 2 commands' in r.message)
    assert not reply.success and reply.commands_pending
    assert '1 of the 2 commands' in reply.message
    asked = pending.pending_replies
    reply = lockstep.ask_until(pending, lambda r: pending.pending_replies > asked)
    assert not reply.success and reply.commands_pending
    assert '1 of the 2 commands' in reply.message
    assert reply.step_count == before.step_count           # nothing ran
    lockstep.send(0.0)                                      # the second one comes after all
    done = lockstep.reply(pending)
    assert done.success and done.step_count == before.step_count + BATCH


def test_a_long_step_request_is_served_in_chunks_while_the_node_serves_the_rest(start_node,
                                                                                 probe):
    """Issue 15, finding 7: steps: 100000 left the node deaf for 35-45 s, and 50 step
    requests sent at once by one client got 16 replies. A long request now runs step_chunk
    steps at a time, the node's other callbacks served in between, and is answered after its
    last chunk; the services keep a deep queue of requests."""
    from geometry_msgs.msg import TwistStamped
    from rosgraph_msgs.msg import Clock
    from sim_interfaces.srv import StepSimulation
    from std_srvs.srv import Trigger

    from helpers import stamp_s, wait_for
    from ros_common.services import SERVICE_QOS
    start_node('sim_node', '-p', 'synchronous:=true', '-p', 'step_chunk:=240',
               '-p', 'clock_publish_rate:=20.0')
    driver = LockStepDriver(probe)
    clock = probe.collect(Clock, '/clock')
    applied = probe.collect(TwistStamped, '/mini_robot/cmd_vel_out')
    before = driver.reply(driver.step(1)).step_count
    steps = 24000                                     # 100 s of simulated time
    probe.service(Trigger, '/sim_node/resume', 30.0)  # (found before, not while it runs)
    long = driver.step(steps)
    wait_for(lambda: clock and stamp_s(clock[-1][1].clock) > 2.0, 60.0, what='stepping')
    # Another service is answered, and a command takes effect, while the request runs. (Not
    # a pause, which would end it: test_sim_api_limits_graph.py.)
    resumed = probe.call(Trigger, '/sim_node/resume', Trigger.Request(), timeout=30.0)
    assert not resumed.success and 'synchronous mode' in resumed.message
    driver.send(0.1)
    wait_for(lambda: any(m.twist.linear.x > 0.0 for _, m in applied), 30.0,
             what='the command applied between chunks')
    assert not long.future.done()
    reply = driver.reply(long, timeout=300.0)
    assert reply.success and reply.step_count == before + steps
    moved = [stamp_s(m.header.stamp) for _, m in applied if m.twist.linear.x > 0.0]
    assert 2.0 < moved[0] < stamp_s(reply.sim_time)
    # A burst: 50 requests from one client at once, every one answered, in order. (The
    # client keeps as many replies as the server: with rclpy's default of 10, a client slow
    # to take them loses the oldest.)
    client = probe.node.create_client(StepSimulation, '/sim_node/step', qos_profile=SERVICE_QOS)
    assert client.wait_for_service(timeout_sec=15.0)
    burst = [client.call_async(StepSimulation.Request(steps=1)) for _ in range(50)]
    wait_for(lambda: all(f.done() for f in burst), 60.0, what='50 replies')
    counts = [f.result().step_count for f in burst]
    assert counts == list(range(reply.step_count + 1, reply.step_count + 51))
