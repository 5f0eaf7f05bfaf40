"""Who may do what in the 3D view: grants from API tokens and signed view links.

viser serves its own page and websocket on its own port and has no authentication hook,
so the view decides per client (per websocket connection) which controls to show.  A
client starts anonymous (scene only).  It gets a :class:`ViewGrant` in one of two ways:

* the API token typed into that client's panel, checked like a REST bearer token;
* a signed view link that the console asks for (``POST /api/view3d/link``) and puts into
  the websocket URL of its embedded view.  The link is an HMAC-SHA256, under a key derived
  from the settings' secret, of (token id, user id, role, expiry, a random nonce); it opens
  one connection, once, before it expires (:data:`LINK_TTL_S`): a link copied out of the
  console (a browser's history, a log, a shoulder) opens nothing once the view has used it.

Either way the grant remembers the API token row it came from, and :meth:`ViewAccess.recheck`
looks that row up again, so a revoked or expired token, a disabled user or a lowered role
removes the controls while the page stays open.  Roles are those of the REST API
(``viewer < operator < engineer``).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import time
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.orm import selectinload

from backend.auth import authenticate, hash_token
from backend.db.models import ApiToken, Role
from backend.db.session import Database
from backend.db.types import utcnow
from backend.knowntokens import KnownTokens
from backend.throttle import SignInThrottle

__all__ = [
    "LINK_PATH_PREFIX",
    "LINK_TTL_S",
    "MAX_SPENT_LINKS",
    "LinkClaims",
    "ViewAccess",
    "ViewGrant",
    "link_from_path",
    "sign_view_link",
    "verify_view_link",
]

#: How long a signed view link may be used to open a connection, seconds.
LINK_TTL_S = 120.0
#: Upper bound accepted for a link's lifetime (a link signed for longer is refused).
MAX_LINK_TTL_S = 3600.0
#: The websocket path that carries a link: ``ws://host:port/vc-link/<link>``.
LINK_PATH_PREFIX = "/vc-link/"
_LINK_VERSION = "v1"
_LINK = re.compile(
    r"^v1\.([0-9]{1,19})\.([0-9]{1,19})\.(viewer|operator|engineer)\.([0-9]{1,12})"
    r"\.([0-9a-f]{16})\.([A-Za-z0-9_-]{43})$"
)
#: Most spent links remembered at once (each until it expires); past it, links are refused
#: until some expire rather than forgotten early (a forgotten link would open again).
MAX_SPENT_LINKS = 10_000
_MAX_DB_ID = 2**63 - 1


@dataclass(frozen=True)
class LinkClaims:
    """What a valid view link says."""

    token_id: int
    """Row id of the API token the console holds (the grant lives as long as it)."""
    user_id: int
    """Owner of that token."""
    role: Role
    """The user's role when the link was signed (the database has the last word)."""
    expires_at: float
    """Unix time after which the link opens no connection, seconds."""
    nonce: str
    """Random per link (16 hex digits): two links signed in the same second differ."""


@dataclass(frozen=True)
class ViewGrant:
    """What one signed-in view client may do."""

    user: str
    """User name, shown in the panel."""
    role: Role
    """Role, as in the REST API."""
    token_id: int | None
    """API token row the grant depends on (None when authentication is disabled)."""
    via: str
    """``"token"`` (typed into the panel), ``"link"`` (signed link) or ``"open"`` (auth off)."""

    def allows(self, role: Role) -> bool:
        """True if this grant holds at least ``role``."""
        return self.role >= role


def _link_key(secret: str) -> bytes:
    # Domain separation: the link key is not the token-hashing key itself.
    return hmac.new(secret.encode(), b"visioncell view3d link v1", hashlib.sha256).digest()


def _signature(payload: str, secret: str) -> str:
    mac = hmac.new(_link_key(secret), payload.encode(), hashlib.sha256).digest()
    return base64.urlsafe_b64encode(mac).rstrip(b"=").decode()


def sign_view_link(
    *,
    token_id: int,
    user_id: int,
    role: Role,
    secret: str,
    ttl_s: float = LINK_TTL_S,
    now: float | None = None,
    nonce: str | None = None,
) -> str:
    """A view link for the holder of API token ``token_id``.

    Parameters
    ----------
    token_id, user_id : int
        Database ids of the token and its user (0 < id < 2**63).
    role : Role
        The user's role.
    secret : str
        The settings' secret key.
    ttl_s : float
        Lifetime of the link, 0 < ttl_s <= MAX_LINK_TTL_S seconds.
    now : float, optional
        Unix time to sign at (default: the clock).
    nonce : str, optional
        16 hex digits making the link unique (default: random).
    """
    for name, value in (("token_id", token_id), ("user_id", user_id)):
        if isinstance(value, bool) or not isinstance(value, int) or not 0 < value <= _MAX_DB_ID:
            raise ValueError(f"{name} must be an integer in 1..2**63-1, got {value!r}")
    if not isinstance(role, Role):
        raise ValueError(f"role must be a Role, got {role!r}")
    if isinstance(ttl_s, bool) or not (0.0 < float(ttl_s) <= MAX_LINK_TTL_S):
        raise ValueError(f"ttl_s must be in (0, {MAX_LINK_TTL_S:g}] seconds, got {ttl_s!r}")
    nonce = secrets.token_hex(8) if nonce is None else nonce
    if not isinstance(nonce, str) or not re.fullmatch(r"[0-9a-f]{16}", nonce):
        raise ValueError(f"nonce must be 16 hex digits, got {nonce!r}")
    expires = int((time.time() if now is None else now) + ttl_s)
    payload = f"{_LINK_VERSION}.{token_id}.{user_id}.{role.name}.{expires}.{nonce}"
    return f"{payload}.{_signature(payload, secret)}"


def verify_view_link(link: str, *, secret: str, now: float | None = None) -> LinkClaims | None:
    """The claims of ``link`` if it is well formed, signed with ``secret`` and unexpired."""
    if not isinstance(link, str) or len(link) > 200:
        return None
    m = _LINK.match(link)
    if m is None:
        return None
    token_id, user_id, role, expires, nonce, sig = m.groups()
    payload = link.rsplit(".", 1)[0]
    if not hmac.compare_digest(sig, _signature(payload, secret)):
        return None
    t = time.time() if now is None else now
    if float(expires) < t or float(expires) > t + MAX_LINK_TTL_S:
        return None
    tid, uid = int(token_id), int(user_id)
    if not (0 < tid <= _MAX_DB_ID and 0 < uid <= _MAX_DB_ID):
        return None
    return LinkClaims(
        token_id=tid, user_id=uid, role=Role[role], expires_at=float(expires), nonce=nonce
    )


def link_from_path(path: str | None) -> str | None:
    """The link carried by a websocket request path (``/vc-link/<link>``), if any."""
    if not path:
        return None
    path = path.split("?", 1)[0]
    if not path.startswith(LINK_PATH_PREFIX):
        return None
    return path[len(LINK_PATH_PREFIX) :] or None


class ViewAccess:
    """Grants for 3D view clients, checked against the database.

    Parameters
    ----------
    db : Database
        Where users and tokens live.
    secret : str
        The settings' secret key (hashes tokens, signs links).
    auth_enabled : bool
        False: every client gets the engineer role, as the REST API does then.
    throttle : SignInThrottle, optional
        Failed sign-ins per client address, shared with the REST API: a bad token typed
        into a panel counts against the browser's address, and a blocked address gets
        :class:`~backend.throttle.TooManyAttempts` even for a correct token.

    Notes
    -----
    All methods are coroutines for the application's event loop (the database engine is
    bound to it); the view calls them from viser's thread with
    ``asyncio.run_coroutine_threadsafe``.
    """

    def __init__(
        self,
        db: Database,
        *,
        secret: str,
        auth_enabled: bool = True,
        throttle: SignInThrottle | None = None,
        known: KnownTokens | None = None,
    ) -> None:
        self.db = db
        self._secret = secret
        self.auth_enabled = auth_enabled
        self.throttle = throttle
        #: Where a token signed in here is noted for the emergency stop (None: nowhere).
        self.known = known
        #: Links already used (their nonce) -> when they expire, unix seconds.
        self._spent: dict[str, float] = {}

    def open_grant(self) -> ViewGrant | None:
        """The grant every client gets without signing in (only when auth is disabled)."""
        if self.auth_enabled:
            return None
        return ViewGrant(user="anonymous", role=Role.engineer, token_id=None, via="open")

    async def from_token(self, token: str, *, client: str | None = None) -> ViewGrant | None:
        """The grant of an API token typed into a panel, or None if it is not valid.

        With ``client`` (the browser's address) the sign-in is throttled: raises
        :class:`~backend.throttle.TooManyAttempts` while that address is blocked, and a
        bad token counts one failure against it.
        """
        throttle = self.throttle if client is not None else None
        if throttle is not None:
            throttle.check(client)  # type: ignore[arg-type]
        if not isinstance(token, str):
            return None
        token = token.strip()
        async with self.db.session() as session:
            user = await authenticate(session, token, self._secret)
            if user is None:
                if throttle is not None:
                    throttle.failure(client)  # type: ignore[arg-type]
                return None
            row = await session.scalar(
                select(ApiToken.id).where(ApiToken.token_hash == hash_token(token, self._secret))
            )
        if row is None:
            return None
        if self.known is not None:
            self.known.note(
                hash_token(token, self._secret), user_id=int(user.id), user=user.name,
                role=user.role,
            )  # fmt: skip
        return ViewGrant(user=user.name, role=Role[user.role], token_id=int(row), via="token")

    def _spend(self, claims: LinkClaims, now: float) -> bool:
        """Mark the link of ``claims`` used; False if it was used before (or too many
        unexpired links are remembered to take one more)."""
        if len(self._spent) >= MAX_SPENT_LINKS:
            self._spent = {n: t for n, t in self._spent.items() if t >= now}
        if claims.nonce in self._spent or len(self._spent) >= MAX_SPENT_LINKS:
            return False
        self._spent[claims.nonce] = claims.expires_at
        return True

    async def from_link(self, link: str, *, now: float | None = None) -> ViewGrant | None:
        """The grant of a signed view link, or None if it is invalid, expired, revoked or
        was used before (a link opens one connection: it is spent here, before the
        database is asked, so two connections racing with one link get one grant)."""
        t = time.time() if now is None else now
        claims = verify_view_link(link, secret=self._secret, now=t)
        if claims is None or not self._spend(claims, t):
            return None
        grant = await self._lookup(claims.token_id, via="link", user_id=claims.user_id)
        if grant is None:
            return None
        # Never more than the link says, never more than the database says.
        return ViewGrant(
            user=grant.user, role=min(grant.role, claims.role), token_id=grant.token_id, via="link"
        )

    async def recheck(self, grant: ViewGrant) -> ViewGrant | None:
        """``grant`` as the database sees it now: None once its token is revoked or its user
        disabled; a lowered role is applied."""
        if grant.token_id is None:
            return self.open_grant()
        fresh = await self._lookup(grant.token_id, via=grant.via)
        if fresh is None:
            return None
        role = min(fresh.role, grant.role) if grant.via == "link" else fresh.role
        return ViewGrant(user=fresh.user, role=role, token_id=fresh.token_id, via=grant.via)

    async def link_for_token(self, token: str, *, ttl_s: float = LINK_TTL_S) -> str | None:
        """A view link for the holder of API ``token`` (None if the token is not valid).

        The link names the token's row, so revoking the token also ends the view's grant.
        """
        grant = await self.from_token(token)
        if grant is None or grant.token_id is None:
            return None
        async with self.db.session() as session:
            row = await session.get(ApiToken, grant.token_id)
            if row is None:
                return None
            user_id = row.user_id
        return sign_view_link(
            token_id=grant.token_id,
            user_id=user_id,
            role=grant.role,
            secret=self._secret,
            ttl_s=ttl_s,
        )

    async def _lookup(
        self, token_id: int, *, via: str, user_id: int | None = None
    ) -> ViewGrant | None:
        """The grant of token row ``token_id`` (owned by ``user_id`` if given), or None."""
        async with self.db.session() as session:
            row = await session.scalar(
                select(ApiToken).options(selectinload(ApiToken.user)).where(ApiToken.id == token_id)
            )
            if row is None or row.revoked or row.user.disabled:
                return None
            if user_id is not None and row.user_id != user_id:
                return None
            if row.expires_at is not None and row.expires_at <= utcnow():
                return None
            return ViewGrant(user=row.user.name, role=Role[row.user.role], token_id=row.id, via=via)
