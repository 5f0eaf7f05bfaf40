"""The OPC UA server of the cell (asyncua), for a line's PLC and the plant's MES.

Address space (namespace ``urn:visioncell:plc``), under ``Objects/VisionCell``, laid out as
OPC 40100-1 (Machine Vision) lays out a vision system where it fits the cell:

- ``StateMachine``: ``CurrentState`` (``Idle``, ``Ready``, ``Executing``, ``Error``,
  ``Stopped by E-STOP``) and ``CurrentStateCode`` (:class:`SystemState`);
- ``Status``: the handshake's flags (``TriggerEnabled``, ``TriggerReady``, ``Busy``,
  ``ResultsValid``, ``Running``, ``EStop``), ``ErrorCode`` / ``ErrorText``, ``Triggers``,
  ``QueuedResults``;
- ``RecipeManagement``: ``ActiveRecipeId`` and the method ``SelectRecipe(UInt16)`` (a line
  changeover: operators, as over REST);
- ``ResultManagement/Result``: the presented result (``InspectionId``, ``TriggerNumber``,
  ``Decision``, ``DecisionCode``, ``Model``, ``ModelId``, ``Score``, ``X_mm``, ``Y_mm``,
  ``Yaw_deg``, ``Bin``, ``BinName``, ``Duration_s``) and the method
  ``AcknowledgeResult(UInt32 inspection id)``; every presented result is also sent as an
  ``InspectionResultEventType`` event from the ``VisionCell`` object;
- methods ``EnableTrigger(Boolean)``, ``Trigger() -> UInt32``, ``StartRun(UInt32 count, 0:
  until stopped)``, ``StopRun()``, ``Reset()``.

A refused command answers ``BadUserAccessDenied`` (role too low) or ``BadInvalidState``
(the handshake's error code and text say why).  OPC 40100's MachineVision nodeset and the DI
nodeset it builds on are loaded (when found in the data directory) so that clients can
browse the companion specification's types.

Process: asyncua builds its address space and parses the nodesets in long synchronous
stretches (seconds), so this server runs in a child process of its own
(:mod:`backend.plc.opcua_link`); its method calls go to the cell's handshake over a pipe, the
handshake's changes come back the same way.  Nothing here ever holds the cell's loop.
The nodes and the values written to them are :mod:`backend.plc.opcua_space`; this module
runs the server: security, sessions, the writer of the handshake's snapshots, the methods.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from backend.db.models import Role
from backend.plc.handshake import ErrorCode, LinkUser, Snapshot
from backend.plc.opcua_access import _hook_sessions, _ruleset, _session_user, _UserManager
from backend.plc.opcua_space import (
    NAMESPACE,
    Var,
    build_address_space,
    fill_event,
    snapshot_values,
    write_order,
)
from backend.plc.signin import Credentials

__all__ = ["NAMESPACE", "OpcUaServer", "nodeset_files"]

log = logging.getLogger(__name__)

#: The server's application URI (in its certificate).
APP_URI = "urn:visioncell:server"
#: Most OPC UA sessions at once.
MAX_SESSIONS = 64
#: The nodesets loaded, in order (DI first: MachineVision builds on it).
NODESETS = ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.MachineVision.NodeSet2.xml")
#: Longest wait for the server's thread to come up or go down, seconds (a hang's bound).
START_BOUND_S = 300.0


def nodeset_files(data_dir: Path) -> list[Path]:
    """The OPC 40100 nodesets under ``data_dir/opcua`` (empty when any is missing)."""
    files = [data_dir / "opcua" / n for n in NODESETS]
    return files if all(f.is_file() for f in files) else []


class OpcUaServer:
    """The OPC UA server (in the child process: see :mod:`backend.plc.opcua_link`).

    Parameters
    ----------
    bridge : Bridge
        The pipe to the cell's process: commands go there, snapshots come from there.
    credentials : Credentials
        The sign-in tables (loaded from the cell's process at each new session).
    endpoint : str
        ``opc.tcp://HOST:PORT[/PATH]``.
    anonymous_read : bool
        Let clients without a user read and subscribe (never call a method).
    nodesets : list of Path
        NodeSet2 files loaded at start, in order.
    throttle : SignInThrottle, optional
        Failed sign-ins per client address.
    security : {"none", "encrypt", "both"}
        Security policies offered: None, Basic256Sha256 SignAndEncrypt, or both.
    cert_dir : Path, optional
        Where the server's certificate and key are kept (made at first start).
    """

    def __init__(self, bridge: Any, credentials: Credentials, *, endpoint: str,
                 anonymous_read: bool = False, nodesets: list[Path] | None = None,
                 throttle: Any = None, security: str = "none",
                 cert_dir: Path | None = None) -> None:  # fmt: skip
        self.bridge = bridge
        self.credentials = credentials
        self.endpoint = endpoint
        self.anonymous_read = anonymous_read
        self.nodesets = list(nodesets or [])
        self.throttle = throttle
        self.security = security
        self.cert_dir = cert_dir
        self.load_s: float | None = None
        """Seconds the nodesets took to load."""
        self.stop_event = asyncio.Event()
        self._snapshots: asyncio.Queue[Snapshot] = asyncio.Queue()
        self._vars: dict[str, Var] = {}
        self._server: Any = None
        self._events: Any = None
        self._last_event_id = 0

    def on_snapshot(self, snap: Snapshot) -> None:
        """A snapshot of the handshake arrived from the cell."""
        self._snapshots.put_nowait(snap)

    async def serve(self, ready: Callable[[float], None]) -> None:
        """Build the address space, listen, call ``ready(load_s)``, serve until
        :attr:`stop_event` is set."""
        from asyncua import Server, ua

        # asyncua logs every request at INFO: the cell's log keeps its warnings only
        logging.getLogger("asyncua").setLevel(max(logging.WARNING, log.getEffectiveLevel()))
        manager: Any = _UserManager(self.credentials, self.anonymous_read)
        server = Server(user_manager=manager)
        await server.init()
        server.set_endpoint(self.endpoint)
        await server.set_application_uri(APP_URI)
        server.set_server_name("VisionCell")
        policies = []
        if self.security in ("none", "both"):
            policies.append(ua.SecurityPolicyType.NoSecurity)
        if self.security in ("encrypt", "both"):
            await self._load_certificate(server)
            policies.append(ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt)
        server.set_security_policy(policies, permission_ruleset=_ruleset(self.anonymous_read))
        from asyncua.server.internal_session import InternalSession

        InternalSession.max_connections = MAX_SESSIONS
        tokens: list[type] = [ua.UserNameIdentityToken]
        if self.credentials.user_certificates is not None:
            tokens.append(ua.X509IdentityToken)
        if self.anonymous_read:
            tokens.append(ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        _hook_sessions(server, self._refresh_credentials, self.throttle, manager)
        t0 = time.perf_counter()
        for path in self.nodesets:
            await server.import_xml(str(path))
        self.load_s = time.perf_counter() - t0
        if self.nodesets:
            log.info("OPC UA: loaded %d nodesets in %.2f s", len(self.nodesets), self.load_s)
        await self._build(server)
        self._server = server
        if self.stop_event.is_set():  # stopped while starting
            return
        async with server:
            ready(self.load_s or 0.0)
            log.info("OPC UA server listening on %s", self.endpoint)
            writer = asyncio.get_running_loop().create_task(self._writer())
            await self.stop_event.wait()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await writer

    async def _load_certificate(self, server: Any) -> None:
        """The server's certificate and key under ``cert_dir`` (self-signed, made once)."""
        from asyncua.crypto.cert_gen import setup_self_signed_certificate
        from cryptography.x509.oid import ExtendedKeyUsageOID

        if self.cert_dir is None:
            raise ValueError("an encrypting security policy needs a folder for the certificate")
        self.cert_dir.mkdir(parents=True, exist_ok=True)
        key, cert = self.cert_dir / "server-key.pem", self.cert_dir / "server-cert.der"
        host = endpoint_host(self.endpoint) or "localhost"
        await setup_self_signed_certificate(
            key, cert, APP_URI, host, [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            {"commonName": "VisionCell OPC UA server", "organizationName": "VisionCell"},
        )  # fmt: skip
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))

    async def _refresh_credentials(self) -> None:
        try:
            by_hash, by_cert = await self.bridge.request("refresh")
            self.credentials.load(by_hash, by_cert)
        except Exception:  # the database is down: the tables read last are used
            log.warning("OPC UA: could not re-read the sign-in tables", exc_info=True)

    async def _build(self, server: Any) -> None:
        space = await build_address_space(
            server,
            {
                "EnableTrigger": self._m_enable,
                "Trigger": self._m_trigger,
                "StartRun": self._m_start_run,
                "StopRun": self._m_stop_run,
                "Reset": self._m_reset,
                "SelectRecipe": self._m_select,
                "AcknowledgeResult": self._m_ack,
            },
        )
        self._vars = space.variables
        self._events = space.event_type
        self._evgen = space.event_generator

    async def _writer(self) -> None:
        """Copy each handshake snapshot into the variables (only what changed) and send an
        event for each newly presented result."""
        from asyncua import ua

        assert self._snapshots is not None
        while True:
            snap = await self._snapshots.get()
            r = snap.result
            values = snapshot_values(snap)
            for name in write_order(values):
                var = self._vars[name]
                value = values[name]
                same = var.value == value or (
                    isinstance(value, float) and isinstance(var.value, float)
                    and math.isnan(value) and math.isnan(var.value)
                )  # fmt: skip
                if same:
                    continue
                var.value = value
                await self._server.write_attribute_value(
                    var.node.nodeid, ua.DataValue(ua.Variant(value, var.vtype))
                )
            if r is not None and snap.results_valid and r.inspection_id != self._last_event_id:
                self._last_event_id = r.inspection_id
                fill_event(self._evgen.event, r)
                await self._evgen.trigger(message=f"inspection {r.inspection_id}: {r.decision}")

    # -- methods (server loop) ------------------------------------------------------------
    def _user(self) -> LinkUser | None:
        user = _session_user.get()
        role = getattr(user, "vc_role", None)
        return None if role is None else LinkUser(str(user.name), role)

    async def _command(self, need: Role, name: str, *args: Any) -> Any:
        """Run the handshake's command ``name`` in the cell's process as the session's user;
        the OPC UA answer: a status code when refused, else ``(value, triggers)``."""
        from asyncua import ua

        user = self._user()
        refused = user is None or int(user.role) < int(need)
        if refused:
            who = "anonymous" if user is None else f"{user.name} ({user.role.name})"
            log.info("OPC UA: %s refused: needs %s", who, need.name)
            if user is None:
                return _status(ua.StatusCodes.BadUserAccessDenied)
        assert user is not None
        ok, error, triggers = await self.bridge.request(
            "cmd", name, (user.name, int(user.role)), args
        )
        if refused or ok is False:
            code = (
                ua.StatusCodes.BadUserAccessDenied
                if refused or error == ErrorCode.ROLE_TOO_LOW
                else ua.StatusCodes.BadInvalidState
            )
            return _status(code)
        return ok, triggers

    async def _m_enable(self, parent: Any, enable: Any) -> Any:
        out = await self._command(Role.operator, "enable", bool(_value(enable)))
        return out if not isinstance(out, tuple) else []

    async def _m_trigger(self, parent: Any) -> Any:
        from asyncua import ua

        out = await self._command(Role.operator, "trigger")
        if isinstance(out, tuple):
            return [ua.Variant(out[1] % 2**32, ua.VariantType.UInt32)]
        return out

    async def _m_start_run(self, parent: Any, count: Any) -> Any:
        out = await self._command(Role.operator, "start_run", int(_value(count)))
        return out if not isinstance(out, tuple) else []

    async def _m_stop_run(self, parent: Any) -> Any:
        out = await self._command(Role.operator, "stop_run")
        return out if not isinstance(out, tuple) else []

    async def _m_reset(self, parent: Any) -> Any:
        out = await self._command(Role.operator, "reset")
        return out if not isinstance(out, tuple) else []

    async def _m_select(self, parent: Any, recipe: Any) -> Any:
        out = await self._command(Role.operator, "select", int(_value(recipe)))
        return out if not isinstance(out, tuple) else []

    async def _m_ack(self, parent: Any, inspection_id: Any) -> Any:
        from asyncua import ua

        user = self._user()
        if user is None or int(user.role) < int(Role.operator):
            return _status(ua.StatusCodes.BadUserAccessDenied)
        took, _error, _n = await self.bridge.request(
            "cmd", "ack", (user.name, int(user.role)), (int(_value(inspection_id)),)
        )
        return [ua.Variant(bool(took), ua.VariantType.Boolean)]


def _status(code: int) -> Any:
    """An OPC UA status code answer (asyncua types the code as its UInt32 alias)."""
    from asyncua import ua

    return ua.StatusCode(code)  # type: ignore[arg-type]


def _value(v: Any) -> Any:
    return getattr(v, "Value", v)


def endpoint_host(endpoint: str) -> str:
    """The host of an ``opc.tcp://`` endpoint."""
    return urlsplit(endpoint).hostname or ""
