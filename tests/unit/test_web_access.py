"""Who may reach the control panel and the live view: the Host and Origin rules, without a
server (the graph tests send the same requests to the running nodes)."""
import pytest

from ros_common.web_access import WebAccess, WebAccessError, split_host

PANEL = WebAccess('127.0.0.1')


def refused(access, host, origin=None, websocket=True):
    refusal = access.check([host] if isinstance(host, str) else host,
                           [] if origin is None else
                           [origin] if isinstance(origin, str) else origin, websocket)
    return None if refusal is None else refusal.status


@pytest.mark.parametrize('host, origin', [
    ('127.0.0.1:8080', 'http://127.0.0.1:8080'),
    ('localhost:8080', 'http://localhost:8080'),
    ('LocalHost.:8080', 'http://localhost:8080'),
    ('[::1]:8080', 'http://[::1]:8080'),
    ('127.0.0.1:8080', None),                   # a client that is not a browser
    ('127.0.0.1', 'http://127.0.0.1'),
])
def test_the_panels_own_page_and_clients_without_a_browser_get_in(host, origin):
    assert refused(PANEL, host, origin) is None


@pytest.mark.parametrize('host, origin, status', [
    # DNS rebinding: the other site's name resolves here, and its page is "same-origin".
    ('evil.example:8080', 'http://evil.example:8080', 403),
    ('evil.example:8080', None, 403),
    ('localhost.evil.example:8080', 'http://localhost.evil.example:8080', 403),
    ('127.0.0.1.nip.io:8080', 'http://127.0.0.1.nip.io:8080', 403),
    # A page of another site, its WebSocket sent to loopback.
    ('127.0.0.1:8080', 'http://evil.example', 403),
    ('127.0.0.1:8080', 'null', 403),                          # a sandboxed frame, a file
    ('127.0.0.1:8080', 'http://127.0.0.1:9999', 403),         # another server on loopback
    ('127.0.0.1:8080', 'https://127.0.0.1:8080.evil.example', 403),
    ('127.0.0.1:8080', 'http://127.0.0.1:8080/path', 403),
    # Headers no browser sends.
    ([], None, 400),
    (['127.0.0.1:8080', '127.0.0.1:8080'], None, 400),
    ('127.0.0.1:8080', ['http://127.0.0.1:8080', 'http://127.0.0.1:8080'], 400),
    ('127.0.0.1:8080@evil.example', None, 400),
    ('evil.example/x', None, 400),
    ('127.0.0.1:99999', None, 400),
    ('127.0.0.1:8O', None, 400),
    ('::1:8080', None, 400),
    ('[::1', None, 400),
    ('', None, 400),
    ('a' * 400, None, 400),
])
def test_other_sites_and_malformed_headers_are_refused(host, origin, status):
    assert refused(PANEL, host, origin) == status


def test_a_plain_page_request_is_checked_for_its_host_only():
    assert refused(PANEL, '127.0.0.1:8080', 'http://evil.example', websocket=False) is None
    assert refused(PANEL, 'evil.example:8080', None, websocket=False) == 403


def test_serving_on_every_interface_takes_any_address_and_the_names_given():
    lan = WebAccess('0.0.0.0', extra_hosts=['robots.lab'])
    assert refused(lan, '192.168.1.20:8080', 'http://192.168.1.20:8080') is None
    assert refused(lan, '[fe80::1]:8080', None) is None
    assert refused(lan, 'robots.lab:8080', 'http://robots.lab:8080') is None
    assert refused(lan, 'evil.example:8080', 'http://evil.example:8080') == 403
    assert refused(lan, '192.168.1.20:8080', 'http://evil.example') == 403
    assert 'any IP address' in lan.describe()
    one = WebAccess('192.168.1.20')
    assert refused(one, '192.168.1.20:8080', None) is None
    assert refused(one, '10.0.0.1:8080', None) == 403
    assert refused(WebAccess('::1'), '[::1]:8080', None) is None


def test_allowed_origins_are_whole_matches_of_the_patterns_given():
    view = WebAccess('127.0.0.1', allowed_origins=[r'https://app\.foxglove\.dev', ''])
    assert refused(view, '127.0.0.1:8765', 'https://app.foxglove.dev') is None
    assert refused(view, '127.0.0.1:8765', 'https://app.foxglove.dev.evil.example') == 403
    assert refused(view, '127.0.0.1:8765', 'http://app.foxglove.dev') == 403
    assert 'https://app\\.foxglove\\.dev' in view.describe()


@pytest.mark.parametrize('kwargs, why', [
    ({'bind_host': 'bad host!'}, 'host'),
    ({'bind_host': '127.0.0.1', 'extra_hosts': ['robots.lab:80']}, 'without a port'),
    ({'bind_host': '127.0.0.1', 'allowed_origins': ['(']}, 'regular expression'),
])
def test_a_bad_rule_is_refused_at_start_up(kwargs, why):
    with pytest.raises(WebAccessError, match=why):
        WebAccess(**kwargs)


def test_host_headers_are_read_as_browsers_write_them():
    assert split_host('Example.COM:80') == ('example.com', 80)
    assert split_host('[::1]') == ('::1', None)
    assert split_host('10.0.0.1') == ('10.0.0.1', None)
    for bad in ('x:', 'x:0', 'x:-1', 'x y', '[1.2.3.4]:80', 'x:²'):
        with pytest.raises(ValueError):
            split_host(bad)
