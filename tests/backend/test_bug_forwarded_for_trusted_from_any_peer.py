"""``X-Forwarded-For`` is believed only from the proxies in ``VISIONCELL_TRUSTED_PROXIES``:
from any other peer (loopback included, which uvicorn trusted by default) the sign-in
throttle keys on the peer, so a client can neither lock out an address it names nor evade
its own block by changing the header; from a trusted proxy the header names the client."""

from __future__ import annotations

import ipaddress

import httpx
import pytest

from backend.api.limits import uvicorn_options
from backend.api.proxies import TrustedProxies
from backend.app import create_app
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.servers import run_uvicorn

BAD = "vc_not-a-token-anyone-has"


def _get(base: str, token: str, forwarded_for: str | None) -> int:
    headers = {"Authorization": f"Bearer {token}"}
    if forwarded_for is not None:
        headers["X-Forwarded-For"] = forwarded_for
    return httpx.get(f"{base}/api/robot/state", headers=headers, timeout=60).status_code


def test_uvicorn_leaves_proxy_headers_to_the_app():
    assert uvicorn_options()["proxy_headers"] is False


def test_the_header_is_ignored_from_an_untrusted_peer(tmp_path):
    s = make_settings(tmp_path)  # no trusted proxies (the default)
    migrate(s)
    good = make_tokens(s)["viewer"]
    with run_uvicorn(create_app(s)) as srv:
        # rotating headers do not spread the failures over many "clients"
        for i in range(s.signin_max_failures):
            assert _get(srv.base, BAD, f"10.9.0.{i}") == 401
        assert _get(srv.base, good, "10.9.0.99") == 429  # the peer is blocked, whatever it says
        assert _get(srv.base, good, None) == 429


def test_the_header_names_the_client_from_a_trusted_proxy(tmp_path):
    s = make_settings(tmp_path, trusted_proxies="127.0.0.1")
    migrate(s)
    good = make_tokens(s)["viewer"]
    with run_uvicorn(create_app(s)) as srv:
        for _ in range(s.signin_max_failures):
            assert _get(srv.base, BAD, "10.9.0.1") == 401
        assert _get(srv.base, good, "10.9.0.1") == 429  # that client is blocked
        assert _get(srv.base, good, "10.9.0.2") == 200  # another client behind the proxy is not
        assert _get(srv.base, good, None) == 200  # nor the proxy itself


@pytest.mark.parametrize(
    ("peer", "header", "client"),
    [
        ("10.0.0.5", "203.0.113.7", "203.0.113.7"),  # one trusted proxy
        ("10.0.0.5", "198.51.100.1, 203.0.113.7", "203.0.113.7"),  # the rightmost untrusted
        ("10.0.0.5", "198.51.100.1, 10.0.0.9", "198.51.100.1"),  # trusted hops skipped
        ("10.0.0.5", "garbage", "10.0.0.5"),  # a malformed entry names nobody
        ("10.0.0.5", "198.51.100.1, garbage, 10.0.0.9", "10.0.0.9"),
        ("10.0.0.5", None, "10.0.0.5"),
        ("192.0.2.1", "203.0.113.7", "192.0.2.1"),  # an untrusted peer: its header ignored
        ("10.0.0.5", "2001:db8::1", "2001:db8::1"),
        ("10.0.0.5", ",".join(["10.0.0.1"] * 100) + ",", "10.0.0.5"),
    ],
)
def test_client_of(peer, header, client):
    mw = TrustedProxies(lambda *a: None, trusted=[ipaddress.ip_network("10.0.0.0/24")])
    assert mw.client_of(peer, header) == client


def test_a_long_chain_is_read_from_the_right_only():
    mw = TrustedProxies(lambda *a: None, trusted=[ipaddress.ip_network("10.0.0.0/24")])
    chain = ", ".join(["203.0.113.9"] + ["10.0.0.7"] * 40)
    assert mw.client_of("10.0.0.5", chain) == "10.0.0.7"  # past the hop limit: the last read
