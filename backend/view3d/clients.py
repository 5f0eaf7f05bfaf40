"""What viser's internals tell of a connected client of the 3D view
(:mod:`backend.view3d.server`): its websocket request's path and its peer address."""

from __future__ import annotations

import viser


def _request_path(server: viser.ViserServer | None, client_id: int) -> str | None:
    """The path (with query) of a client's websocket request, or None.

    viser 1.1 has no public accessor for it; the connection object it keeps per client
    (a ``websockets`` ``ServerConnection``) carries the opening request.  If a later viser
    changes these internals, this answers None and clients sign in with a token instead.
    """
    ws_server = getattr(server, "_websock_server", None)
    conn = getattr(ws_server, "_live_connections", {}).get(client_id)
    request = getattr(conn, "request", None)
    path = getattr(request, "path", None)
    return path if isinstance(path, str) else None


def _client_address(server: viser.ViserServer | None, client_id: int) -> str | None:
    """The peer address of a client's websocket (the sign-in throttle's key), or None
    (same viser internals as :func:`_request_path`)."""
    ws_server = getattr(server, "_websock_server", None)
    conn = getattr(ws_server, "_live_connections", {}).get(client_id)
    remote = getattr(conn, "remote_address", None)
    if isinstance(remote, tuple) and remote and isinstance(remote[0], str):
        return remote[0]
    return None
