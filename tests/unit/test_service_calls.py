"""ros_common.services.call_and_wait: a lost reply to an idempotent request is asked again
(Fast DDS drops a reply when the server has not yet matched the client's reply reader)."""
import threading
from concurrent.futures import Future

import pytest

from ros_common.services import NoAnswer, call_and_wait


class FakeClient:
    """Answers the requests whose numbers are in ``answered`` (from 0), after ``delay``."""

    srv_name = '/fake/solve'

    def __init__(self, answered, delay=0.0):
        self.answered, self.delay = set(answered), delay
        self.sent, self.removed = [], []

    def call_async(self, request):
        future = Future()
        n = len(self.sent)
        self.sent.append(request)
        if n in self.answered:
            threading.Timer(self.delay, future.set_result, args=(f'reply {n}',)).start()
        return future

    def remove_pending_request(self, future):
        self.removed.append(future)


def test_an_answered_call_is_sent_once():
    client = FakeClient({0})
    assert call_and_wait(client, 'req', timeout=5.0, resend=0.2) == 'reply 0'
    assert client.sent == ['req'] and client.removed == []


def test_a_lost_reply_is_asked_again_and_the_first_answer_taken():
    client = FakeClient({2})                # the first two replies are lost
    assert call_and_wait(client, 'req', timeout=5.0, resend=0.05) == 'reply 2'
    assert client.sent == ['req'] * 3
    assert len(client.removed) == 2         # the unanswered copies are forgotten


def test_without_resend_a_lost_reply_times_out_with_one_request():
    client = FakeClient({1})
    with pytest.raises(NoAnswer, match='/fake/solve did not answer within 0.2 s'):
        call_and_wait(client, 'step', timeout=0.2)
    assert client.sent == ['step']          # (a step is never sent twice)


def test_resending_stops_at_the_timeout_and_says_how_often():
    client = FakeClient(set())
    with pytest.raises(NoAnswer, match=r'within 0.3 s \(\d+ requests\)'):
        call_and_wait(client, 'req', timeout=0.3, resend=0.1)
    assert 3 <= len(client.sent) <= 5


def test_a_shutdown_ends_the_wait():
    client = FakeClient(set())
    with pytest.raises(NoAnswer):
        call_and_wait(client, 'req', timeout=30.0, resend=0.05, ok=lambda: False)
    assert len(client.sent) == 1


class ServedClient(FakeClient):
    def wait_for_service(self, timeout_sec):
        return True


def test_a_coordinator_stopped_in_a_call_ends_its_run_as_interrupted(monkeypatch):
    """Ctrl-C or SIGTERM while the coordinator waits for a service: the run was stopped (it
    ends as interrupted), not a node that did not answer (node_timeout, exit 1)."""
    from coordinator import ros_ports
    stopped = threading.Event()
    monkeypatch.setattr(ros_ports.rclpy, 'ok', lambda: not stopped.is_set())
    with pytest.raises(ros_ports.NodeTimeout, match='did not answer'):
        ros_ports.call_service(ServedClient(set()), 'req', 'IK', timeout=0.3)
    threading.Timer(0.1, stopped.set).start()
    with pytest.raises(ros_ports.Stopped):
        ros_ports.call_service(ServedClient(set()), 'req', 'IK', timeout=0.3)
