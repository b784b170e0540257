"""Answer a service request later, from another callback, without a thread.

rclpy's executors (the EventsExecutor every node here spins, and the SingleThreadedExecutor)
call the service's callback and then ``service.send_response(response, header)``. A callback
that returns :meth:`DeferredReplies.later` makes that call keep the request's header instead
of sending; :meth:`DeferredReplies.send` answers it when the work is done. The node serves its
other callbacks in between, which a callback that did all the work first could not.
"""
from __future__ import annotations

from typing import Any, Dict


class _Later:
    """What a callback returns to answer later; ``key`` names the request."""

    __slots__ = ('key',)

    def __init__(self, key: Any) -> None:
        self.key = key


class DeferredReplies:
    """Deferred replies of one rclpy ``Service``."""

    def __init__(self, service: Any) -> None:
        self._service = service
        self._send = service.send_response
        self._headers: Dict[Any, Any] = {}
        service.send_response = self._send_or_keep

    def later(self, key: Any) -> _Later:
        """Return this from the service callback to answer the request later, by ``key``."""
        return _Later(key)

    def send(self, key: Any, response: Any) -> None:
        """Answer the request deferred under ``key``."""
        self._send(response, self._headers.pop(key))

    @property
    def waiting(self) -> int:
        return len(self._headers)

    def _send_or_keep(self, response: Any, header: Any) -> None:
        if isinstance(response, _Later):
            if response.key in self._headers:
                raise ValueError(f'a reply is already deferred under {response.key!r}')
            self._headers[response.key] = header
        else:
            self._send(response, header)
