"""Start and stop the PLC links the settings ask for (OPC UA, Modbus TCP) over a runtime.

Both are off by default; :func:`plc_links` is entered by the app's lifespan
(:func:`backend.app.create_app`) after the cell runtime, and exited before it.  The Modbus
server binds at once (a port taken stops the start-up with a :class:`StartupError`); the
OPC UA server comes up in a child process of its own a few seconds later (the console and
the E-STOP do not wait for it; a failure is logged as an error).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

from backend.db.models import Role

__all__ = ["PlcLinks", "plc_links"]

log = logging.getLogger(__name__)


@dataclass
class PlcLinks:
    """The links running now (None: off)."""

    opcua: Any = None
    modbus: Any = None
    handshakes: list[Any] = field(default_factory=list)


@contextlib.asynccontextmanager
async def plc_links(rt: Any) -> AsyncIterator[PlcLinks]:
    """Run the links ``rt.settings`` enables for as long as the context is entered."""
    from backend.runtime import StartupError

    s = rt.settings
    links = PlcLinks()
    if s.opcua_endpoint is None and s.modbus_port is None:
        yield links
        return
    from backend.plc.handshake import Handshake

    async with contextlib.AsyncExitStack() as stack:
        if s.opcua_endpoint is not None:
            from backend.plc.opcua import nodeset_files
            from backend.plc.opcua_link import OpcUaLink
            from backend.plc.signin import Credentials

            hs = Handshake(rt, name="opcua", max_queue=s.plc_result_queue)
            await hs.start()
            stack.push_async_callback(hs.stop)
            hs.set_trigger_enable(True)  # OPC UA triggers by method: enabled unless disabled
            creds = Credentials(rt.database, s.secret_key.get_secret_value(),
                                user_certificates=s.opcua_user_certificates)  # fmt: skip
            await creds.refresh(force=True)
            throttle = {"max_failures": s.signin_max_failures, "window_s": s.signin_window_s,
                        "block_s": s.signin_block_s, "max_clients": s.signin_max_clients}  # fmt: skip
            link = OpcUaLink(
                hs, creds, endpoint=s.opcua_endpoint,
                anonymous_read=s.opcua_anonymous == "read-only",
                nodesets=nodeset_files(s.data_dir) if s.opcua_nodesets else [],
                throttle=throttle, security=s.opcua_security, cert_dir=s.var_dir / "opcua",
                secret=s.secret_key.get_secret_value(),
            )  # fmt: skip
            await link.start()  # listening a few seconds later, off the cell's loop
            stack.push_async_callback(link.stop)
            links.opcua = link
            links.handshakes.append(hs)
        if s.modbus_port is not None:
            from backend.plc.modbus import ModbusLink

            hs = Handshake(rt, name="modbus", max_queue=s.plc_result_queue)
            await hs.start()
            stack.push_async_callback(hs.stop)
            mlink = ModbusLink(hs, host=s.modbus_host, port=s.modbus_port, role=Role[s.modbus_role])
            try:
                await mlink.start()
            except Exception as exc:
                await mlink.stop()
                raise StartupError(
                    f"cannot serve Modbus TCP on {s.modbus_host}:{s.modbus_port}: {exc}"
                ) from exc
            stack.push_async_callback(mlink.stop)
            links.modbus = mlink
            links.handshakes.append(hs)
        rt.plc_links = links  # CellRuntime.plc_links: where in-process tools find them
        try:
            yield links
        finally:
            rt.plc_links = None
