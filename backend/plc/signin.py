"""Sign-in of a PLC or an MES over OPC UA: a VisionCell user's name and one of its API tokens.

A certificate signs a user in too: ``VISIONCELL_OPCUA_USER_CERTIFICATES`` names a folder of
``NAME.der`` / ``NAME.pem`` files; a client whose X509 identity token is one of them acts as
the enabled user ``NAME``.

VisionCell users have no passwords: a program signs in with a token issued to it
(``visioncell user add plc --role operator`` prints one).  OPC UA's user-name identity
token carries the user's name and, as the password, that token; the pair is accepted when
the token is live (neither revoked nor expired), its user is enabled and has that name.
The session then acts with the user's role (viewer reads; operator also triggers, runs,
resets and selects recipes; engineer the same, since recipes are edited elsewhere).

OPC UA servers check a sign-in synchronously (asyncua's ``UserManager.get_user``), so the
check reads a table of the live tokens' HMACs held in memory; :meth:`Credentials.refresh`
re-reads it from the database (asynchronously, when a client opens a session, before it
signs in), so a token issued or revoked a moment ago is honoured on the next connection.
"""

from __future__ import annotations

import asyncio
import hmac
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import select

from backend.auth import hash_token, live_token_clause, well_formed
from backend.db.models import ApiToken, Role, User

__all__ = ["MAX_CERTIFICATES", "MAX_CREDENTIALS", "Credential", "Credentials", "read_certificates"]

#: Most user certificates read from the folder, and the largest file, bytes.
MAX_CERTIFICATES = 256
MAX_CERTIFICATE_BYTES = 64 * 1024

log = logging.getLogger(__name__)

#: Most live tokens held for sign-ins.
MAX_CREDENTIALS = 100_000


def read_certificates(folder: Path) -> dict[bytes, str]:
    """The certificates ``NAME.der`` / ``NAME.pem`` in ``folder`` as DER bytes -> user name
    (at most :data:`MAX_CERTIFICATES`, each at most :data:`MAX_CERTIFICATE_BYTES`; files
    that are no certificate, or whose stem is no user name, are skipped with a warning)."""
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding

    from backend.auth import validate_user_name

    out: dict[bytes, str] = {}
    if not folder.is_dir():
        log.warning("OPC UA user certificates: %s is not a folder", folder)
        return out
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".der", ".pem"))
    for path in files[:MAX_CERTIFICATES]:
        try:
            name = validate_user_name(path.stem)
            if path.stat().st_size > MAX_CERTIFICATE_BYTES:
                raise ValueError(f"larger than {MAX_CERTIFICATE_BYTES} bytes")
            data = path.read_bytes()
            cert = (x509.load_pem_x509_certificate(data) if path.suffix.lower() == ".pem"
                    else x509.load_der_x509_certificate(data))  # fmt: skip
            out[cert.public_bytes(Encoding.DER)] = name
        except (ValueError, OSError) as exc:
            log.warning("OPC UA user certificate %s skipped: %s", path.name, exc)
    return out


@dataclass(frozen=True)
class Credential:
    """A live token's user."""

    name: str
    role: Role


class Credentials:
    """The live tokens' HMACs and their users (thread-safe: checked on the OPC UA thread).

    Parameters
    ----------
    database : Database
        Where users and tokens are stored.
    secret : str
        The tokens' HMAC key (``Settings.secret_key``).
    min_refresh_s : float
        Shortest interval between two reads of the table (many connections at once read it
        once).
    clock : callable, optional
        Monotonic seconds.
    """

    def __init__(self, database: Any, secret: str, *, min_refresh_s: float = 0.5,
                 user_certificates: Path | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:  # fmt: skip
        self._db = database
        self._secret = secret
        self.user_certificates = user_certificates
        self._by_hash: dict[str, Credential] = {}
        self._by_cert: dict[bytes, Credential] = {}
        self._lock = threading.Lock()
        self._min_refresh_s = float(min_refresh_s)
        self._clock = clock
        self._last: float | None = None
        self.failures = 0

    async def refresh(self, *, force: bool = False) -> int:
        """Re-read the live tokens of enabled users; returns how many are held."""
        now = self._clock()
        if not force and self._last is not None and now - self._last < self._min_refresh_s:
            return len(self._by_hash)
        async with self._db.session() as session:
            rows = await session.execute(
                select(ApiToken.token_hash, User.name, User.role)
                .join(User, ApiToken.user_id == User.id)
                .where(live_token_clause(), User.disabled.is_(False))
                .limit(MAX_CREDENTIALS)
            )
            table = {str(h): Credential(str(n), Role[str(r)]) for h, n, r in rows.all()}
            certs: dict[bytes, Credential] = {}
            if self.user_certificates is not None:
                files = await asyncio.to_thread(read_certificates, self.user_certificates)
                users = dict(
                    (await session.execute(
                        select(User.name, User.role).where(
                            User.name.in_(list(files.values())), User.disabled.is_(False)
                        )
                    )).all()
                )  # fmt: skip
                certs = {der: Credential(n, Role[str(users[n])]) for der, n in files.items()
                         if n in users}  # fmt: skip
        with self._lock:
            self._by_hash = table
            self._by_cert = certs
            self._last = now
        return len(table)

    def tables(self) -> tuple[dict[str, Credential], dict[bytes, Credential]]:
        """The tables read last (token HMAC -> user, certificate -> user)."""
        with self._lock:
            return dict(self._by_hash), dict(self._by_cert)

    def load(self, by_hash: dict[str, Credential], by_cert: dict[bytes, Credential]) -> None:
        """Take tables read by another process (:meth:`tables`)."""
        with self._lock:
            self._by_hash, self._by_cert = dict(by_hash), dict(by_cert)

    def check_certificate(self, der: object) -> Credential | None:
        """The user whose certificate (``user_certificates``/NAME.der or .pem) is ``der``."""
        if not isinstance(der, bytes | bytearray):
            return None
        with self._lock:
            cred = self._by_cert.get(bytes(der))
        if cred is None:
            self.failures += 1
        return cred

    def check(self, name: object, password: object) -> Credential | None:
        """The credential when ``password`` is a live token of the user called ``name``."""
        if not isinstance(name, str) or not isinstance(password, str | bytes):
            return None
        token = password.decode("utf-8", "replace") if isinstance(password, bytes) else password
        if not well_formed(token) or len(name) > 64:
            self.failures += 1
            return None
        with self._lock:
            cred = self._by_hash.get(hash_token(token, self._secret))
        if cred is None or not hmac.compare_digest(cred.name.encode(), name.encode()):
            self.failures += 1
            return None
        return cred
