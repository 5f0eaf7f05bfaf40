"""The client's address behind a reverse proxy, believed only from a trusted proxy.

The sign-in throttle (:mod:`backend.throttle`) keys on the client's address.  If any peer
could name that address in ``X-Forwarded-For``, a client could lock out an address it
names (five bad tokens "from" it) and evade its own block by changing the header on every
request.  So the header is used only when the peer is one of the proxies listed in
``VISIONCELL_TRUSTED_PROXIES`` (addresses or networks, none by default), and uvicorn's
own proxy-header handling, which trusts loopback peers, is off (``uvicorn_options``).

:class:`TrustedProxies`, a pure ASGI middleware, rewrites the connection's client address
for a request from a trusted proxy: the header's entries are read from the right (the one
the trusted proxy appended last), trusted proxies are skipped, and the first other address
is the client.  A malformed entry ends the walk at the last trusted hop, so the peer (or
the proxy before it) stays the client: a header cannot invent an address by being garbled.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Sequence

from starlette.types import ASGIApp, Receive, Scope, Send

from backend.settings import MAX_TRUSTED_PROXIES, Network, parse_trusted_proxies

__all__ = ["MAX_HOPS", "MAX_TRUSTED_PROXIES", "TrustedProxies", "parse_trusted_proxies"]

#: Most ``X-Forwarded-For`` entries read, from the right (a longer chain is cut there).
MAX_HOPS = 16
#: Longest ``X-Forwarded-For`` value read, bytes (anything beyond is ignored).
_MAX_HEADER = 2048


def _address(text: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(text.strip())
    except ValueError:
        return None


class TrustedProxies:
    """Pure ASGI middleware: the client address from ``X-Forwarded-For``, only when the
    peer is a trusted proxy (see the module doc).

    Parameters
    ----------
    app : ASGI app
        The application behind it.
    trusted : sequence of networks
        The trusted proxies (:func:`parse_trusted_proxies`); empty: the header is never used.
    """

    def __init__(self, app: ASGIApp, *, trusted: Sequence[Network]) -> None:
        self.app = app
        self.trusted = tuple(trusted)

    def _trusted(self, host: str) -> bool:
        ip = _address(host)
        return ip is not None and any(ip in net for net in self.trusted)

    def client_of(self, peer: str, forwarded_for: str | None) -> str:
        """The client address of a connection from ``peer`` with this header value."""
        if forwarded_for is None or not self._trusted(peer):
            return peer
        hops = forwarded_for[:_MAX_HEADER].split(",")[-MAX_HOPS:]
        client = peer
        for hop in reversed(hops):
            ip = _address(hop)
            if ip is None:
                break
            client = str(ip)
            if not self._trusted(client):
                break
        return client

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] in ("http", "websocket") and self.trusted and scope.get("client"):
            values = [v for k, v in scope.get("headers", ()) if k == b"x-forwarded-for"]
            header = b",".join(values).decode("latin-1") if values else None
            host = scope["client"][0]
            client = self.client_of(host, header)
            if client != host:
                scope = dict(scope)
                scope["client"] = (client, 0)
        await self.app(scope, receive, send)
