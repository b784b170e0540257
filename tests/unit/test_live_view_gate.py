"""The live view's gate in front of the Foxglove SDK's server (no ROS): a subscription the SDK
refuses because the channel is not registered yet is sent again (live_view/gate.py)."""
import asyncio
import json
import time

import foxglove
import pytest
import websockets

from live_view.bridge import SlowClients
from live_view.gate import (
    RESUBSCRIBE_S,
    RESUBSCRIBE_TRIES,
    Gate,
    Resubscriber,
    self_signed_certificate,
)
from ros_common.web_access import WebAccess


def _refusal(channel):
    return json.dumps({'op': 'status', 'level': 2, 'message': f'Unknown channel ID: {channel}'})


def test_a_refused_subscription_is_sent_again_a_bounded_number_of_times():
    subs = Resubscriber()
    subs.sent(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': 3, 'channelId': 8}]}))
    again = [subs.again(_refusal(8)) for _ in range(RESUBSCRIBE_TRIES + 1)]
    assert again[:-1] == [json.dumps({'op': 'subscribe',
                                      'subscriptions': [{'id': 3, 'channelId': 8}]})] * len(
        again[:-1]) and again[-1] is None
    # Another channel's refusal, a refusal of a channel never subscribed, other statuses: none.
    assert subs.again(_refusal(9)) is None
    assert subs.again(json.dumps({'op': 'status', 'level': 0, 'message': 'hello'})) is None
    # Unsubscribed: not sent again.
    subs.sent(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': 4, 'channelId': 10}]}))
    subs.sent(json.dumps({'op': 'unsubscribe', 'subscriptionIds': [4]}))
    assert subs.again(_refusal(10)) is None


@pytest.mark.parametrize('frame', [
    b'\x00binary', 'not json', '[1, 2]', '{"op": 5}', '{"op": "subscribe", "subscriptions": 7}',
    '{"op": "subscribe", "subscriptions": [[], {"channelId": "8"}]}',
    '{"op": "unsubscribe", "subscriptionIds": [{}, [], 1]}'])
def test_what_a_client_may_send_never_breaks_the_bookkeeping(frame):
    subs = Resubscriber()
    subs.sent(frame)
    assert subs.again(frame) is None and subs.again(_refusal(8)) is None


def test_a_client_that_subscribes_before_the_sdk_has_the_channel_still_gets_its_messages():
    """A client subscribes to a channel the SDK does not have yet (as one did that subscribed
    the moment the channel was advertised, under load: "attempted to subscribe to unknown
    channel", and no odometry for 30 s); the channel comes 0.5 s later. Through the gate the
    client gets its messages."""
    certificate, key = self_signed_certificate()
    server = foxglove.start_server(name='test', host='127.0.0.1', port=0, tls_cert=certificate,
                                   tls_key=key)
    lines = []
    gate = Gate(WebAccess('127.0.0.1'), '127.0.0.1', 0, server.port, certificate, 4, 1_000_000,
                SlowClients(), lambda level, text, kind: lines.append(text))
    port = gate.start()
    first = foxglove.Channel('/first', message_encoding='json')
    later = None

    async def session():
        nonlocal later
        async with websockets.connect(f'ws://127.0.0.1:{port}',
                                      subprotocols=['foxglove.sdk.v1']) as ws:
            await asyncio.sleep(0.2)
            # (Channel ids are handed out in order: the next is the first's plus one.)
            await ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 1, 'channelId': first.id() + 1}]}))
            await asyncio.sleep(0.5)
            later = foxglove.Channel('/later', message_encoding='json')
            assert later.id() == first.id() + 1
            end = time.monotonic() + 10.0
            while time.monotonic() < end:
                later.log(b'{"k": 1}')
                try:
                    frame = await asyncio.wait_for(ws.recv(), 0.1)
                except asyncio.TimeoutError:
                    continue
                if isinstance(frame, bytes) and frame[0] == 1:     # (a message's data)
                    return True
            return False

    try:
        assert asyncio.run(session())
    finally:
        gate.stop()
        server.stop()
    assert RESUBSCRIBE_S * RESUBSCRIBE_TRIES >= 1.0
