"""Who may reach the project's web servers (the control panel, the live view): the Host and
Origin rules that keep a web page of another site from driving or watching the robots.

Two attacks reach a server on loopback from the user's own browser:

- a page of another site opens a WebSocket to ``127.0.0.1``: the browser sends that site's
  ``Origin``, which must be refused (the same-origin policy does not cover WebSockets);
- DNS rebinding: the other site's name is made to resolve to ``127.0.0.1``, so its page is
  "same-origin" with the server (``Host: evil.example:8080`` and ``Origin:
  http://evil.example:8080`` agree). Only the ``Host`` header gives it away: it names a host
  that is not this server.

So every request must name one of the server's own hosts (loopback names, the address it is
bound to, and names the user adds; any IP address when it serves on every interface, since an
address cannot be rebound), and a browser's WebSocket must come from a page of the server
itself or of an origin the user allowed. Clients that are not browsers send no ``Origin``
and are let in (a script on this machine can reach the robots over DDS anyway).
"""
from __future__ import annotations

import ipaddress
import re
import socket
import urllib.parse
from dataclasses import dataclass
from typing import Iterable, Optional, Sequence, Tuple, Union

LOOPBACK_NAMES = ('localhost', '127.0.0.1', '::1')
WILDCARD_ADDRESSES = ('0.0.0.0', '::', '')
# RFC 3986's reg-name, as a browser sends it in Host (letters, digits, '-', '.', '_').
_PORT = re.compile(r'[0-9]{1,5}')
_NAME = re.compile(r'[a-z0-9_]([a-z0-9_.-]{0,252})?')


class WebAccessError(ValueError):
    """An access rule that cannot be used (a bad host name or origin pattern)."""


@dataclass(frozen=True)
class Refusal:
    """Why a request is refused: the HTTP status to answer with and a reason for the log."""

    status: int
    reason: str


def _ip(name: str) -> Optional[Union[ipaddress.IPv4Address, ipaddress.IPv6Address]]:
    try:
        return ipaddress.ip_address(name)
    except ValueError:
        return None


def split_host(value: str) -> Tuple[str, Optional[int]]:
    """A Host header (or an origin's authority) as (host name, port): lower case, an IPv6
    address without its brackets, no trailing dot. Raises ValueError if it is not one."""
    value = value.strip().lower()
    if not value or len(value) > 300 or any(c in value for c in '/\\@?#% \t'):
        raise ValueError(f'not a host: {value!r}')
    port_text: Optional[str]
    if value.startswith('['):
        host, bracket, rest = value[1:].partition(']')
        address = _ip(host)
        if not bracket or address is None or address.version != 6:
            raise ValueError(f'not an IPv6 address: {value!r}')
        if rest and not rest.startswith(':'):
            raise ValueError(f'not a host: {value!r}')
        port_text = rest[1:] if rest else None
    else:
        host, colon, port_text = value.partition(':')
        if not colon:
            port_text = None
        elif ':' in port_text:
            raise ValueError(f'an IPv6 address needs brackets: {value!r}')
        host = host.rstrip('.')
        if _ip(host) is None and not _NAME.fullmatch(host):
            raise ValueError(f'not a host name: {value!r}')
    port: Optional[int] = None
    if port_text is not None:
        if not _PORT.fullmatch(port_text) or not 0 < int(port_text) < 65536:
            raise ValueError(f'not a port: {value!r}')
        port = int(port_text)
    return host, port


class WebAccess:
    """The Host and Origin rules of one server (see the module's docstring)."""

    def __init__(self, bind_host: str, extra_hosts: Sequence[str] = (),
                 allowed_origins: Sequence[str] = ()) -> None:
        names = set(LOOPBACK_NAMES)
        self.any_address = bind_host.strip() in WILDCARD_ADDRESSES
        if self.any_address:
            # Served on every interface: reached by this machine's name too.
            names.add(socket.gethostname().lower())
        else:
            names.add(self._host_name(bind_host, 'host'))
        for extra in extra_hosts:
            if extra.strip():
                names.add(self._host_name(extra, 'allowed_hosts'))
        self.hosts = frozenset(names)
        try:
            self.origins = tuple(re.compile(pattern) for pattern in allowed_origins
                                 if pattern.strip())
        except re.error as exc:
            raise WebAccessError(f'allowed_origins: not a regular expression: {exc}') from None

    @staticmethod
    def _host_name(value: str, what: str) -> str:
        address = _ip(value.strip())
        if address is not None:              # (an IPv6 address as a parameter: no brackets)
            return str(address)
        try:
            host, port = split_host(value)
        except ValueError as exc:
            raise WebAccessError(f'{what}: {exc}') from None
        if port is not None:
            raise WebAccessError(f'{what}: a host name without a port, got {value!r}')
        return host

    def describe(self) -> str:
        hosts = ', '.join(sorted(self.hosts)) + (', any IP address' if self.any_address else '')
        origins = ', '.join(p.pattern for p in self.origins)
        return f'hosts {hosts}; origins: its own' + (f', {origins}' if origins else '')

    def host_allowed(self, host: str) -> bool:
        return host in self.hosts or (self.any_address and _ip(host) is not None)

    def check(self, hosts: Iterable[str], origins: Iterable[str],
              websocket: bool) -> Optional[Refusal]:
        """A request's Host and Origin headers (every value each appears with): None if it
        may go on, else the refusal. ``websocket``: the Origin is checked too (a browser's
        plain page request carries none that matters)."""
        hosts, origins = list(hosts), list(origins)
        if len(hosts) != 1:
            return Refusal(400, f'{len(hosts)} Host headers (HTTP/1.1 requires exactly one)')
        try:
            host, _port = split_host(hosts[0])
        except ValueError as exc:
            return Refusal(400, f'bad Host header: {exc}')
        if not self.host_allowed(host):
            return Refusal(403, f'Host {hosts[0][:100]!r} is not this server (a web page '
                           'that made its own name resolve here: DNS rebinding)')
        if not websocket or not origins:
            return None
        if len(origins) > 1:
            return Refusal(400, f'{len(origins)} Origin headers')
        origin = origins[0].strip()
        if self._same_origin(origin, hosts[0]) or any(p.fullmatch(origin)
                                                      for p in self.origins):
            return None
        return Refusal(403, f'Origin {origin[:100]!r} is not allowed (a page of another '
                       'site; allowed_origins adds one)')

    @staticmethod
    def _same_origin(origin: str, host_header: str) -> bool:
        parts = urllib.parse.urlsplit(origin)
        if parts.scheme not in ('http', 'https') or parts.path or parts.query:
            return False
        try:
            return split_host(parts.netloc) == split_host(host_header)
        except ValueError:
            return False
