"""A simulated PLC: the programs a line controller runs against the cell's PLC links, written
with the real client libraries (pymodbus's and asyncua's clients).

:class:`ModbusPlc` walks the register handshake as a PLC's scan would (write a control bit,
poll the status word until the cell answers), :class:`OpcUaPlc` calls the methods and waits
on a subscription.  Both return each result with the wall time from the trigger to the
result being readable, and are used by ``benchmarks/plc.py`` and the tests.  Every wait is
bounded by ``bound_s`` (a hang's bound, not a timing requirement).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from backend.plc.modbus import CONTROL_BITS, N_REGISTERS, STATUS_AT, STATUS_BITS, decode_result

__all__ = ["ModbusPlc", "OpcUaPlc", "PlcRefused", "Triggered", "make_client_certificate"]

#: The simulated PLC's application URI (in its certificate).
CLIENT_URI = "urn:visioncell:simulated-plc"


async def make_client_certificate(folder: Path, name: str = "plc") -> tuple[Path, Path]:
    """A self-signed client certificate and key for :class:`OpcUaPlc` (made once in
    ``folder``, as ``NAME-cert.der`` and ``NAME-key.pem``)."""
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    folder.mkdir(parents=True, exist_ok=True)
    key, cert = folder / f"{name}-key.pem", folder / f"{name}-cert.der"
    await setup_self_signed_certificate(key, cert, CLIENT_URI, "localhost",
                                        [ExtendedKeyUsageOID.CLIENT_AUTH],
                                        {"commonName": f"simulated PLC {name}"})  # fmt: skip
    return cert, key


#: Status words read in one request (registers 10..28).
_N_STATUS = N_REGISTERS - STATUS_AT


class PlcRefused(RuntimeError):
    """The cell refused a command; ``code`` is its error code."""

    def __init__(self, code: int, text: str = "") -> None:
        super().__init__(f"refused with error code {code}{': ' + text if text else ''}")
        self.code = code


@dataclass(frozen=True)
class Triggered:
    """One trigger's result as the PLC read it."""

    result: dict[str, Any]
    """The result words (``decode_result``'s keys: inspection_id, decision, x_m, ...)."""
    latency_s: float
    """From the trigger's write or call to the result being readable."""


class ModbusPlc:
    """A PLC program over Modbus TCP (see the module docstring)."""

    def __init__(self, host: str, port: int, *, poll_s: float = 0.002, bound_s: float = 600.0,
                 clock: Callable[[], float] = time.perf_counter) -> None:  # fmt: skip
        from pymodbus.client import AsyncModbusTcpClient

        self.client = AsyncModbusTcpClient(host, port=port, timeout=10)
        self.poll_s = poll_s
        self.bound_s = bound_s
        self.clock = clock
        self.control = 0

    async def connect(self) -> None:
        """Open the connection (``ConnectionError`` when the server does not answer)."""
        if not await self.client.connect():
            raise ConnectionError("the Modbus server did not answer")

    def close(self) -> None:
        """Close the connection."""
        self.client.close()

    async def read(self) -> dict[str, Any]:
        """The status and result words, decoded; ``flags``: the set status bits' names."""
        rr = await self.client.read_holding_registers(STATUS_AT, count=_N_STATUS)
        if rr.isError():
            raise ConnectionError(f"read failed: {rr}")
        out = decode_result(list(rr.registers))
        out["flags"] = {k for k, b in STATUS_BITS.items() if out["status"] >> b & 1}
        return out

    async def write(self, address: int, value: int) -> Any:
        """Write one register; returns the response (an exception response when refused)."""
        return await self.client.write_register(address, value)

    async def set_bits(self, **bits: bool) -> None:
        """Set or clear CONTROL bits by name (``TRIGGER=True``)."""
        for name, on in bits.items():
            mask = 1 << CONTROL_BITS[name]
            self.control = self.control | mask if on else self.control & ~mask
        rr = await self.write(0, self.control)
        if rr.isError():
            raise ConnectionError(f"write failed: {rr}")

    async def wait(self, check: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        """Poll until ``check(words)``; ``TimeoutError`` naming ``what`` after ``bound_s``."""
        t0 = time.monotonic()
        while True:
            words = await self.read()
            if check(words):
                return words
            if time.monotonic() - t0 > self.bound_s:
                raise TimeoutError(f"Modbus: no {what} within {self.bound_s:g} s: {words}")
            await asyncio.sleep(self.poll_s)

    async def trigger(self) -> Triggered:
        """One full handshake: wait for Trigger Ready, trigger, take the result, acknowledge."""
        if not self.control >> CONTROL_BITS["TRIGGER_ENABLE"] & 1:
            await self.set_bits(TRIGGER_ENABLE=True)

        def ready_or_refused(w: dict[str, Any]) -> bool:
            # errors 2 and 3 (busy, result not acknowledged) pass as the cell catches up
            refused = "ERROR" in w["flags"] and w["error"] not in (0, 2, 3)
            return "TRIGGER_READY" in w["flags"] or refused

        w = await self.wait(ready_or_refused, "trigger ready")
        if "TRIGGER_READY" not in w["flags"]:
            raise PlcRefused(w["error"])
        before = w["triggers"]
        t0 = self.clock()
        await self.set_bits(TRIGGER=True)
        w = await self.read()
        if "TRIGGER_ACK" not in w["flags"] or w["triggers"] == before:
            await self.set_bits(TRIGGER=False)
            raise PlcRefused(w["error"])
        number = w["triggers"]
        await self.set_bits(TRIGGER=False)

        def answered(w: dict[str, Any]) -> bool:
            mine = "RESULTS_VALID" in w["flags"] and w["result_trigger"] == number
            failed = not w["flags"] & {"BUSY", "RESULTS_VALID"} and w["error"] != 0
            return mine or failed

        w = await self.wait(answered, "result")
        latency = self.clock() - t0
        if "RESULTS_VALID" not in w["flags"]:
            raise PlcRefused(w["error"])
        await self.acknowledge()
        return Triggered(w, latency)

    async def acknowledge(self) -> None:
        """Results Ack up, wait for Results Valid to drop, Results Ack down."""
        await self.set_bits(RESULTS_ACK=True)
        await self.wait(lambda w: "RESULTS_VALID" not in w["flags"], "results valid drop")
        await self.set_bits(RESULTS_ACK=False)


class OpcUaPlc:
    """A PLC (or MES) program over OPC UA (see the module docstring)."""

    def __init__(self, url: str, *, user: str | None, password: str | None,
                 bound_s: float = 600.0, publish_ms: float = 10.0,
                 certificate: tuple[Path, Path] | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:  # fmt: skip
        from asyncua import Client

        self.client = Client(url, timeout=30)
        self.certificate = certificate
        """(certificate, private key) of the client: connect over Basic256Sha256
        SignAndEncrypt (None: the None policy)."""
        self.sign_in_with_certificate = certificate is not None and user is None
        """No user name with a certificate: the certificate signs in (X509 identity)."""
        if user is not None:
            self.client.set_user(user)
            self.client.set_password(password or "")
        self.bound_s = bound_s
        self.publish_ms = publish_ms
        self.clock = clock
        self.values: dict[str, Any] = {}
        self.seen_at: dict[str, float] = {}
        self._changed: asyncio.Event | None = None
        self.nodes: dict[str, Any] = {}
        self._sub: Any = None

    async def connect(self) -> None:
        """Connect, sign in, find the nodes and subscribe to the state and result."""
        from backend.plc.opcua import NAMESPACE

        self._changed = asyncio.Event()
        if self.certificate is not None:
            cert, key = self.certificate
            self.client.application_uri = CLIENT_URI
            await self.client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
            if self.sign_in_with_certificate:  # the certificate is the identity too
                await self.client.load_client_certificate(str(cert))
                await self.client.load_private_key(Path(key))
        await self.client.connect()
        idx = await self.client.get_namespace_index(NAMESPACE)
        cell = await self.client.nodes.objects.get_child([f"{idx}:VisionCell"])
        self.nodes["cell"] = cell
        paths = {
            "CurrentState": "StateMachine", "CurrentStateCode": "StateMachine",
            "TriggerReady": "Status", "Busy": "Status", "ResultsValid": "Status",
            "Running": "Status", "EStop": "Status", "ErrorCode": "Status", "ErrorText": "Status",
            "Triggers": "Status", "QueuedResults": "Status", "ActiveRecipeId": "RecipeManagement",
        }  # fmt: skip
        for name, group in paths.items():
            self.nodes[name] = await cell.get_child([f"{idx}:{group}", f"{idx}:{name}"])
        for name in ("InspectionId", "TriggerNumber", "Decision", "DecisionCode", "Model",
                     "ModelId", "Score", "X_mm", "Y_mm", "Yaw_deg", "Bin", "Duration_s"):  # fmt: skip
            self.nodes[name] = await cell.get_child(
                [f"{idx}:ResultManagement", f"{idx}:Result", f"{idx}:{name}"]
            )
        for name, group in (("SelectRecipe", "RecipeManagement"),
                            ("AcknowledgeResult", "ResultManagement")):  # fmt: skip
            self.nodes[name] = await cell.get_child([f"{idx}:{group}", f"{idx}:{name}"])
        for name in ("Trigger", "StartRun", "StopRun", "Reset", "EnableTrigger"):
            self.nodes[name] = await cell.get_child([f"{idx}:{name}"])
        names = {self.nodes[n].nodeid: n for n in ("CurrentState", "CurrentStateCode",
                                                   "ResultsValid", "TriggerNumber", "EStop",
                                                   "InspectionId", "Busy", "ErrorCode")}  # fmt: skip
        plc = self

        class Handler:
            def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
                name = names.get(node.nodeid)
                if name is not None:
                    plc.values[name] = val
                    plc.seen_at[name] = plc.clock()
                    assert plc._changed is not None
                    plc._changed.set()

        self._sub = await self.client.create_subscription(self.publish_ms, Handler())
        await self._sub.subscribe_data_change([self.nodes[n] for n in names.values()],
                                              sampling_interval=0)  # fmt: skip

    async def close(self) -> None:
        """Disconnect."""
        await self.client.disconnect()

    async def call(self, name: str, *args: Any) -> Any:
        """Call a method of the cell (the asyncua error when the server refuses it)."""
        return await self.nodes["cell"].call_method(self.nodes[name], *args)

    async def wait(self, check: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        """Wait for the subscription's values to satisfy ``check``; bounded by ``bound_s``."""
        assert self._changed is not None
        t0 = time.monotonic()
        while not check(self.values):
            self._changed.clear()
            left = self.bound_s - (time.monotonic() - t0)
            if left <= 0:
                raise TimeoutError(f"OPC UA: no {what} within {self.bound_s:g} s: {self.values}")
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), left)
        return self.values

    async def read_result(self) -> dict[str, Any]:
        """The presented result's variables (one read)."""
        names = ["InspectionId", "TriggerNumber", "Decision", "Model", "ModelId", "Score",
                 "X_mm", "Y_mm", "Yaw_deg", "Bin", "Duration_s"]  # fmt: skip
        vals = await self.client.read_values([self.nodes[n] for n in names])
        out = dict(zip(names, vals, strict=True))

        def si(v: float, k: float) -> float | None:
            return None if v is None or math.isnan(v) else v * k

        return {
            "inspection_id": int(out["InspectionId"]), "trigger": int(out["TriggerNumber"]),
            "decision": out["Decision"], "model": out["Model"] or None, "model_id": out["ModelId"],
            "score": si(out["Score"], 1.0), "x_m": si(out["X_mm"], 1e-3),
            "y_m": si(out["Y_mm"], 1e-3), "yaw_rad": si(out["Yaw_deg"], math.pi / 180),
            "bin": out["Bin"], "duration_s": out["Duration_s"],
        }  # fmt: skip

    async def trigger(self) -> Triggered:
        """Call Trigger, wait for its result, read it, acknowledge it."""
        t0 = self.clock()
        number = int(await self.call("Trigger"))

        def answered(v: dict[str, Any]) -> bool:
            # a trigger refused answers the call with an error; once taken, only the
            # inspection's failure (6) or an E-STOP (4) ends it without a result (an older
            # refusal's code may still be in the subscription's values)
            mine = v.get("ResultsValid") is True and v.get("TriggerNumber") == number
            return mine or (v.get("ErrorCode", 0) in (4, 6) and not v.get("Busy"))

        await self.wait(answered, "result")
        latency = self.clock() - t0
        if not self.values.get("ResultsValid"):
            raise PlcRefused(int(self.values.get("ErrorCode", 0)))
        res = await self.read_result()
        await self.acknowledge(res["inspection_id"])
        return Triggered(res, latency)

    async def acknowledge(self, inspection_id: int) -> bool:
        """Acknowledge the presented result."""
        return bool(await self.call_ack(inspection_id))

    async def call_ack(self, inspection_id: int) -> Any:
        from asyncua import ua

        node = self.nodes["AcknowledgeResult"]
        parent = await node.get_parent()
        return await parent.call_method(node, ua.Variant(inspection_id, ua.VariantType.UInt32))
