"""How the simulator's time advances, as services of ``sim_node``: real-time pacing from a
timer, ``~/pause`` and ``~/resume``, and lock-step ``~/step`` requests (served a chunk at a time,
answered after their last chunk, each once the commands announced with it are in)."""
from __future__ import annotations

import collections
import time
from dataclasses import dataclass
from typing import Any, Callable, Deque, Optional, Tuple

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sim_interfaces.srv import StepSimulation
from std_srvs.srv import Trigger

from controllers.lockstep import CommandBarrier
from ros_common.deferred_reply import DeferredReplies
from ros_common.services import SERVICE_QOS
from ros_common.stamps import stamp_from_ns
from sim_bridge.pacing import Pacer, RtfMeter
from sim_bridge.runner import SimRunner, StepSink

MAX_STEPS_PER_REQUEST = 100_000
# Step requests waiting to be served at once (all clients, both services and the action): as
# many as a service keeps per client (ros_common/services.py).
MAX_WAITING_STEPS = 256


@dataclass(eq=False)
class StepJob:
    """Steps served in chunks: a ~/step request and the reply it will get, or steps asked
    for through the simulation interfaces, with what to call as they progress and at their
    end (``on_done(job)``; ``job.stepped``: the steps taken, ``job.canceled``)."""
    steps: int
    remaining: int
    request: Optional[StepSimulation.Request] = None
    response: Optional[StepSimulation.Response] = None
    on_done: Optional[Callable[['StepJob'], None]] = None
    on_progress: Optional[Callable[['StepJob'], None]] = None
    started: bool = False
    canceled: bool = False
    # Why the job was ended before its last step by something else than its own cancel (a
    # pause, a stop, a reset): '' if it was not.
    ended_by: str = ''

    @property
    def stepped(self) -> int:
        return self.steps - self.remaining

    def cancel(self) -> None:
        """End the job after its current chunk."""
        self.canceled = True


class Stepping:
    """The node's clockwork: steps the runner (whose outputs go to ``sink``) in real time, or
    on request in lock-step (``synchronous``) or while paused."""

    def __init__(self, node: Node, runner: SimRunner, sink: StepSink, actions, *,
                 synchronous: bool, time_step: float, real_time_factor: float,
                 max_steps_per_tick: int, step_chunk: int, rtf_log_period: float) -> None:
        self._node, self._runner, self._sink, self._actions = node, runner, sink, actions
        self._world = runner.world
        self.synchronous = synchronous
        self.paused = False
        # Stopped (the simulation interfaces' STATE_STOPPED): reset and paused, until it plays
        # or steps.
        self.stopped = False
        self._pacer = Pacer(time_step, real_time_factor, max_steps_per_tick)
        self._rtf = RtfMeter()
        self._rtf_log_period = rtf_log_period
        self._last_rtf_log = time.monotonic()
        # A step runs once the commands announced with it are in (lockstep.py); until then it
        # is answered at once with commands_pending, and asked again.
        self._barrier = CommandBarrier()
        node.create_service(Trigger, '~/pause', self._on_pause, qos_profile=SERVICE_QOS)
        node.create_service(Trigger, '~/resume', self._on_resume, qos_profile=SERVICE_QOS)
        step = node.create_service(StepSimulation, '~/step', self._on_step,
                                   qos_profile=SERVICE_QOS)
        # A request of more than step_chunk steps (or one behind it) is served a chunk at a
        # time from a timer, the node's other callbacks in between, and answered after its
        # last chunk (the node is never deaf for a long request).
        self._replies = DeferredReplies(step)
        self._jobs: Deque[StepJob] = collections.deque()
        self._chunk = step_chunk
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._chunk_timer = node.create_timer(0.001, self._on_chunk, clock=steady)
        self._chunk_timer.cancel()
        # The simulator is the time source: it paces itself on the steady wall clock.
        period = 0.0 if real_time_factor == 0.0 else time_step / real_time_factor
        self._timer = node.create_timer(period, self._on_tick, clock=steady)
        if synchronous:
            # Lock-step steps only on request: a timer firing at the physics rate for nothing
            # wakes the executor 240 times a second.
            self._timer.cancel()

    def describe(self) -> str:
        rtf = self._pacer.real_time_factor
        return ('lock-step (synchronous)' if self.synchronous else
                'as fast as possible' if rtf == 0.0 else f'real-time factor {rtf:g}')

    @property
    def state(self) -> str:
        """playing, paused or stopped (lock-step: paused, as it steps only on request)."""
        if self.stopped:
            return 'stopped'
        return 'paused' if self.synchronous or self.paused else 'playing'

    @property
    def stepping(self) -> bool:
        """Step requests are being served."""
        return bool(self._jobs)

    @property
    def full(self) -> bool:
        """As many step requests wait as are served at once: a further one is refused."""
        return len(self._jobs) >= MAX_WAITING_STEPS

    def command_arrived(self) -> None:
        """A command (cmd_vel, a trajectory) came in: counted for the step that waits for it."""
        self._barrier.arrived()

    # --- real time ----------------------------------------------------------------------------
    def _on_tick(self) -> None:
        if self.synchronous or self.paused:
            return
        wall = time.monotonic()
        if self._pacer.as_fast_as_possible:
            # Step for about 2 ms, then let the executor serve callbacks.
            deadline = wall + 0.002
            steps = 0
            while steps < self._pacer.max_burst and time.monotonic() < deadline:
                self._runner.advance(1, self._sink)
                steps += 1
        else:
            steps = self._pacer.steps_due(wall)
            self._runner.advance(steps, self._sink)
            self._pacer.record(steps)
        if steps:
            self._note_progress()

    def _note_progress(self) -> None:
        wall = time.monotonic()
        self._rtf.add(wall, self._world.sim_time)
        if self._rtf_log_period > 0.0 and wall - self._last_rtf_log >= self._rtf_log_period:
            self._last_rtf_log = wall
            rtf = self._rtf.value()
            if rtf is not None:
                self._node.get_logger().info(f'real-time factor {rtf:.2f} '
                                             f'(sim time {self._world.sim_time:.1f} s)')

    def pause(self) -> Tuple[bool, str]:
        """Stop real-time stepping (running trajectory goals end: the arms hold); step
        requests being served end too (in lock-step, that is all a pause does)."""
        ended = self.end_steps('a pause')
        if self.synchronous:
            if ended:
                return True, f'paused: {ended}'
            return False, 'synchronous mode: use ~/step'
        self.paused = True
        self._timer.cancel()
        aborted = self._actions.abort_all(
            'the simulation was paused: the arm holds where it is; send the goal again '
            'after ~/resume', hold=True)
        return True, f'paused at {self._world.sim_time:.3f} s' + (
            f' (goals aborted: {", ".join(aborted)})' if aborted else '') + (
            f'; {ended}' if ended else '')

    def end_steps(self, cause: str) -> str:
        """End every step request being served, now: each is answered with the steps it took
        (a pause, a stop and a reset do this before they act, so that what they reply has
        happened and no step follows it). What was ended, as text ('' if nothing was)."""
        ended = []
        while self._jobs:
            job = self._jobs.popleft()
            job.canceled, job.ended_by = True, cause
            if job.started:
                self._end_step()
            ended.append(f'{job.stepped} of {job.steps}')
            if job.response is not None:
                job.response.success = False
                job.response.message = (f'ended by {cause} after {job.stepped} of {job.steps} '
                                        'steps')
            self._finish(job)
        self._chunk_timer.cancel()
        if not ended:
            return ''
        self._node.get_logger().info(f'{cause} ended the step requests being served (steps '
                                     f'taken: {", ".join(ended)})')
        return f'step requests ended after {", ".join(ended)} steps'

    def play(self) -> Tuple[bool, str]:
        """Step in real time again."""
        if self.synchronous:
            return False, 'synchronous mode: use ~/step'
        if self._jobs:
            # (Both would step the world: the reply's step count would not be the request's.)
            left = sum(job.remaining for job in self._jobs)
            return False, (f'step requests are being served ({left} steps left): resume after '
                           'their reply')
        self.paused = self.stopped = False
        self._pacer.restart()
        self._rtf.reset()
        self._timer.reset()
        return True, 'resumed'

    def _on_pause(self, _request, response):
        response.success, response.message = self.pause()
        return response

    def _on_resume(self, _request, response):
        response.success, response.message = self.play()
        return response

    # --- on request ---------------------------------------------------------------------------
    def _on_step(self, request, response):
        if request.steps == 0:
            # A round trip that steps nothing, and may be sent again: a client's first reply
            # can be lost right after discovery (ros_common.services), a step's must not.
            response.success, response.message = True, 'no steps asked for: none taken'
        elif not (self.synchronous or self.paused):
            response.success = False
            response.message = 'step needs synchronous:=true or a paused simulation'
        elif not (1 <= request.steps <= MAX_STEPS_PER_REQUEST):
            response.success = False
            response.message = f'steps must be within 1..{MAX_STEPS_PER_REQUEST}'
        elif self.full:
            response.success = False
            response.message = (f'{MAX_WAITING_STEPS} step requests wait already: ask again '
                                'after their replies')
        elif self._jobs or request.steps > self._chunk:
            job = StepJob(request.steps, request.steps, request, response)
            self._jobs.append(job)
            self._chunk_timer.reset()
            return self._replies.later(job)
        elif self._claim_commands(request, response):
            self.stopped = False
            self._runner.advance(request.steps, self._sink)
            self._end_step()
            response.success = True
        _stamp(response, self._world)
        return response

    def submit(self, steps: int, on_done: Callable[[StepJob], None],
               on_progress: Optional[Callable[[StepJob], None]] = None) -> Optional[StepJob]:
        """Step ``steps`` times (in chunks, after any step request before), calling
        ``on_progress`` after each chunk and ``on_done`` at the end; None if the simulation
        plays in real time (it must be paused, stopped or lock-step)."""
        if not (self.synchronous or self.paused):
            return None
        job = StepJob(steps, steps, on_done=on_done, on_progress=on_progress)
        self._jobs.append(job)
        self._chunk_timer.reset()
        return job

    def _claim_commands(self, request, response) -> bool:
        """Whether the commands announced with a step request are in (taking them if so);
        if not, ``response`` says so and asks the caller to try again."""
        if not self._barrier.ready(request.commands):
            response.success, response.commands_pending = False, True
            response.message = (f'{self._barrier.received} of the {request.commands} commands '
                                'announced for this step have arrived; not stepped, ask again')
            return False
        claim = self._barrier.claim(request.commands)
        if request.commands > 0 and claim.surplus:
            self._node.get_logger().warn(
                f'{claim.received} commands arrived for a step announced with '
                f'{claim.expected}: another node commands this lock-step run, which is '
                'then not reproducible', throttle_duration_sec=5.0)
        return True

    def _end_step(self) -> None:
        self._runner.tick_clock(self._sink)       # (the batch's end, if off the clock's grid)
        self._note_progress()

    def _on_chunk(self) -> None:
        """Run the next chunk of the oldest step request waiting; answer it after its last."""
        if not self._jobs:
            self._chunk_timer.cancel()
            return
        job = self._jobs[0]
        if self._chunk_of(job):
            self._jobs.popleft()
            if job.canceled:
                self._end_step()
            self._finish(job)
        if not self._jobs:
            self._chunk_timer.cancel()

    def _chunk_of(self, job: StepJob) -> bool:
        """Step a chunk of ``job`` (after claiming a ~/step request's commands); whether the
        job is over (all stepped, canceled, or its commands not in yet)."""
        if job.canceled:
            return True
        if not job.started:
            job.started = True
            if job.request is not None and job.response is not None and not \
                    self._claim_commands(job.request, job.response):
                return True
        self.stopped = False
        steps = min(job.remaining, self._chunk)
        self._runner.advance(steps, self._sink)
        job.remaining -= steps
        if job.remaining:
            if job.on_progress is not None:
                job.on_progress(job)
            return False
        self._end_step()
        if job.response is not None:
            job.response.success = True
        return True

    def _finish(self, job: StepJob) -> None:
        if job.response is not None:
            _stamp(job.response, self._world)
            self._replies.send(job, job.response)
        elif job.on_done is not None:
            job.on_done(job)


def _stamp(response: Any, world: Any) -> None:
    """A step reply's step count and simulated time: the world's now."""
    response.step_count = world.step_count
    response.sim_time = stamp_from_ns(world.sim_time_ns)
