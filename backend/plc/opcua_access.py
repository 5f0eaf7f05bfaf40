"""Who may do what on the OPC UA server (:mod:`backend.plc.opcua`): the user manager over
the cell's credentials, the permission rules, and the session hooks that re-read the
sign-in table, throttle failed sign-ins and make the session's user known to the methods."""

from __future__ import annotations

import contextvars
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from backend.plc.signin import Credentials

log = logging.getLogger(__name__)

_session_user: contextvars.ContextVar[Any] = contextvars.ContextVar("opcua_user", default=None)


def _hook_sessions(server: Any, refresh: Callable[[], Awaitable[None]], throttle: Any,
                   manager: Any) -> None:  # fmt: skip
    """Re-read the sign-in table when a session is created (before it signs in), count
    failed sign-ins per client address in ``throttle`` (REST's rule, the server's own count:
    a blocked address is refused before its credentials are looked at), and make the session's user known to the method callbacks of its calls."""
    from asyncua import ua
    from asyncua.common.utils import ServiceError

    refused = {ua.StatusCodes.BadUserAccessDenied, ua.StatusCodes.BadIdentityTokenInvalid,
               ua.StatusCodes.BadIdentityTokenRejected}  # fmt: skip
    iserver = server.iserver
    make = iserver.create_session

    def create_session(*args: Any, **kwargs: Any) -> Any:
        session = make(*args, **kwargs)
        create, call, activate = session.create_session, session.call, session.activate_session
        peer = session.name[0] if isinstance(session.name, tuple) else str(session.name)
        client = f"opcua:{peer}"

        def activate_hooked(*a: Any, **kw: Any) -> Any:
            params = a[0] if a else kw.get("params")
            token = getattr(params, "UserIdentityToken", None)
            # the user manager is told which kind of identity it checks (asyncua hands it
            # the channel's certificate with every kind); no await between here and there
            manager.token_kind = "x509" if isinstance(token, ua.X509IdentityToken) else "other"
            if throttle is not None:
                try:
                    throttle.check(client)
                except Exception:
                    log.warning("OPC UA: sign-in from %s refused: too many failures", peer)
                    raise ServiceError(ua.StatusCodes.BadUserAccessDenied) from None
            try:
                return activate(*a, **kw)
            except ServiceError as exc:
                if throttle is not None and exc.code in refused:
                    throttle.failure(client)
                raise

        async def create_hooked(*a: Any, **kw: Any) -> Any:
            await refresh()
            return await create(*a, **kw)

        async def call_hooked(params: Any) -> Any:
            token = _session_user.set(session.user)
            try:
                return await call(params)
            finally:
                _session_user.reset(token)

        session.create_session, session.call = create_hooked, call_hooked
        session.activate_session = activate_hooked
        return session

    iserver.create_session = create_session


def _ruleset(anonymous_read: bool) -> Any:
    """Signed-in users read, subscribe and call (each method checks the role); anonymous
    clients read and subscribe when allowed, nothing else; nobody changes the address space."""
    from asyncua import ua
    from asyncua.crypto.permission_rules import USER_TYPES, SimpleRoleRuleset, UserRole

    def ids(types: Any) -> set[Any]:
        return {ua.NodeId(t) for t in types}

    oid = ua.ObjectIds
    rules = SimpleRoleRuleset()
    users = ids(USER_TYPES)
    rules._permission_dict[UserRole.Admin] = set(users)
    rules._permission_dict[UserRole.User] = set(users)
    calls = ids((oid.CallRequest_Encoding_DefaultBinary, oid.WriteRequest_Encoding_DefaultBinary))
    session_only = ids((oid.CreateSessionRequest_Encoding_DefaultBinary,
                        oid.ActivateSessionRequest_Encoding_DefaultBinary,
                        oid.CloseSessionRequest_Encoding_DefaultBinary,
                        oid.GetEndpointsRequest_Encoding_DefaultBinary,
                        oid.FindServersRequest_Encoding_DefaultBinary,
                        oid.CloseSecureChannelRequest_Encoding_DefaultBinary))  # fmt: skip
    rules._permission_dict[UserRole.Anonymous] = (users - calls) if anonymous_read else session_only
    return rules


class _UserManager:
    """asyncua's user manager over :class:`Credentials`."""

    def __init__(self, credentials: Credentials, anonymous_read: bool) -> None:
        self.credentials = credentials
        self.anonymous_read = anonymous_read
        self.token_kind = "other"
        """The identity token being checked: ``x509`` or another kind (set just before)."""

    def get_user(self, iserver: Any, username: Any = None, password: Any = None,
                 certificate: Any = None) -> Any:  # fmt: skip
        from asyncua.crypto.permission_rules import User, UserRole

        if self.token_kind == "x509":
            cred = None if certificate is None else self.credentials.check_certificate(certificate)
            if cred is None:
                log.warning("OPC UA: sign-in refused for a certificate of no user")
                return None
            user = User(role=UserRole.User, name=cred.name)
            user.vc_role = cred.role  # type: ignore[attr-defined]
            return user
        if username is None and password is None:
            if not self.anonymous_read:
                return None
            user = User(role=UserRole.Anonymous, name="anonymous")
            user.vc_role = None  # type: ignore[attr-defined]
            return user
        cred = self.credentials.check(username, password)
        if cred is None:
            log.warning("OPC UA: sign-in refused for user name %r", str(username)[:64])
            return None
        user = User(role=UserRole.User, name=cred.name)
        user.vc_role = cred.role  # type: ignore[attr-defined]
        return user
