"""Security headers on every HTTP answer, and CORS (closed unless configured).

The console's policy allows scripts, styles and connections from its own origin only (no
inline script or style: ``web/`` has none), frames from its own origin and from the viser
3D view (same host as the page, the view's port), and lets only its own origin frame it.
The offline API documentation pages (``/docs``, ``/redoc``) start their script inline and
ReDoc runs a worker from a ``blob:`` URL, so they get a policy of their own that allows
that, and still nothing from another origin.
"""

from __future__ import annotations

from fastapi import FastAPI
from starlette.middleware.cors import CORSMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.settings import Settings

__all__ = ["DOCS_PATHS", "SecurityHeaders", "console_policy", "docs_policy", "install_cors"]

#: Pages served with :func:`docs_policy`.
DOCS_PATHS = ("/docs", "/redoc")

_COMMON = {
    b"x-content-type-options": b"nosniff",
    b"referrer-policy": b"no-referrer",
    b"x-frame-options": b"SAMEORIGIN",
}


def console_policy(host: str, viser_port: int, *, scheme: str = "http") -> str:
    """The Content-Security-Policy of the console and the API, for a page at ``host``."""
    view = f"{scheme}://{host}:{viser_port}"
    return (
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
        f"connect-src 'self'; frame-src 'self' {view}; child-src 'self' {view}; "
        "object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'self'"
    )


def docs_policy() -> str:
    """The policy of the documentation pages (inline bootstrap script, ReDoc's worker)."""
    return (
        "default-src 'self'; script-src 'self' 'unsafe-inline'; "
        "style-src 'self' 'unsafe-inline'; img-src 'self' data:; worker-src 'self' blob:; "
        "connect-src 'self'; object-src 'none'; base-uri 'self'; frame-ancestors 'self'"
    )


def _host_of(scope: Scope) -> str:
    for name, value in scope.get("headers", []):
        if name == b"host":
            host = value.decode("latin-1")
            if host.startswith("["):  # IPv6 literal
                return host.split("]", 1)[0] + "]"
            return host.rsplit(":", 1)[0] if host.count(":") == 1 else host
    server = scope.get("server")
    return str(server[0]) if server else "localhost"


def _safe_host(host: str) -> str:
    # Only host characters may reach the header (a forged Host must not inject directives).
    ok = all(c.isalnum() or c in ".-[]:" for c in host) and 0 < len(host) <= 255
    return host if ok else "localhost"


class SecurityHeaders:
    """ASGI middleware adding the security headers to every HTTP answer."""

    def __init__(self, app: ASGIApp, *, viser_port: int) -> None:
        self.app = app
        self.viser_port = viser_port

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path = scope.get("path", "")
        if path in DOCS_PATHS or path.startswith("/docs/"):
            policy = docs_policy()
        else:
            scheme = "https" if scope.get("scheme") == "https" else "http"
            policy = console_policy(_safe_host(_host_of(scope)), self.viser_port, scheme=scheme)
        extra = {**_COMMON, b"content-security-policy": policy.encode()}

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                present = {k.lower() for k, _ in message.get("headers", [])}
                headers = list(message.get("headers", []))
                headers += [(k, v) for k, v in extra.items() if k not in present]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def install_cors(app: FastAPI, settings: Settings) -> bool:
    """Add CORS for ``settings.cors_origins`` (none by default: no middleware, so a
    cross-origin preflight gets no ``Access-Control-Allow-Origin``).  True if added."""
    if not settings.cors_origins:
        return False
    app.add_middleware(
        CORSMiddleware,
        allow_origins=list(settings.cors_origins),
        allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
        allow_headers=["Authorization", "Content-Type"],
        allow_credentials=False,
        max_age=600,
    )
    return True
