"""The Modbus TCP server of the cell (pymodbus): the vision sensors' PLC handshake in registers.

One block of 16-bit registers, the same for holding (function codes 3, 6, 16) and input
registers (function code 4); addresses are 0-based.  The PLC writes the control registers
(0-2); the rest is read-only (a write there answers exception 2, illegal address).

======= ================= ===============================================================
Address Name              Meaning
======= ================= ===============================================================
0       CONTROL           PLC -> cell, bits: 0 TRIGGER_ENABLE, 1 TRIGGER (rising edge:
                          inspect once), 2 RESULTS_ACK (rising: the result was read;
                          falling: show the next), 3 RUN (rising: start a continuous run
                          of RUN_COUNT objects; falling: stop it after the current object),
                          4 RESET (rising: clear the error and a latched E-STOP),
                          5 RECIPE_SELECT (rising: activate recipe RECIPE_REQUEST)
1       RECIPE_REQUEST    recipe number for RECIPE_SELECT (1..65535)
2       RUN_COUNT         objects of a run started by RUN (0: until RUN falls)
3-9     (reserved)        read as 0
10      STATUS            cell -> PLC, bits: 0 ONLINE, 1 TRIGGER_READY, 2 TRIGGER_ACK,
                          3 BUSY, 4 RESULTS_VALID, 5 ERROR, 6 ESTOP, 7 RUNNING,
                          8 RESULTS_OVERFLOW, 9 TRIGGER_ENABLED (echo)
11      STATE             0 idle, 1 ready, 2 executing, 3 error, 4 stopped by E-STOP
12      ERROR_CODE        :class:`~backend.plc.handshake.ErrorCode` (0: none)
13      RECIPE_ID         the active recipe's number (0: none)
14      TRIGGER_COUNT     triggers taken, modulo 65536
15-16   INSPECTION_ID     the presented result's inspection id, unsigned 32-bit, high word first
17      DECISION          0 none, 1 recognized, 2 unknown, 3 failed
18      MODEL_ID          the recognised model's id (0: none)
19-20   X                 object x in the robot base frame, signed 32-bit, 0.01 mm
21-22   Y                 object y, signed 32-bit, 0.01 mm
23      YAW               rotation about base z, signed 16-bit, 0.01 deg (-18000..17999)
24      BIN               1-based bin of the layout the object went to (0: not sorted)
25      SCORE             recognition score x 1000 (0..1000)
26      DURATION          the inspection's duration, ms (saturates at 65535)
27      QUEUED            results waiting behind the presented one
28      RESULT_TRIGGER    the trigger number that asked for the result (0: a run's), mod 65536
======= ================= ===============================================================

X, Y and YAW read INT32_MIN / INT16_MIN (0x8000...) when the inspection has no pose.

Modbus has no sign-in: the server acts with one configured role (operator by default),
binds the loopback interface unless configured otherwise, and should sit on the cell's
own network segment (docs/plc.md).
"""

from __future__ import annotations

import contextlib
import logging
import math
from typing import Any

from backend.db.models import Role
from backend.plc.handshake import ErrorCode, Handshake, LinkUser, Snapshot

__all__ = ["CONTROL_BITS", "REGISTERS", "STATUS_BITS", "ModbusLink", "decode_result", "encode"]

log = logging.getLogger(__name__)

#: Control register bits (address 0).
CONTROL_BITS = {"TRIGGER_ENABLE": 0, "TRIGGER": 1, "RESULTS_ACK": 2, "RUN": 3, "RESET": 4,
                "RECIPE_SELECT": 5}  # fmt: skip
#: Status register bits (address 10).
STATUS_BITS = {"ONLINE": 0, "TRIGGER_READY": 1, "TRIGGER_ACK": 2, "BUSY": 3, "RESULTS_VALID": 4,
               "ERROR": 5, "ESTOP": 6, "RUNNING": 7, "RESULTS_OVERFLOW": 8,
               "TRIGGER_ENABLED": 9}  # fmt: skip
#: Address of each named register.
REGISTERS = {"CONTROL": 0, "RECIPE_REQUEST": 1, "RUN_COUNT": 2, "STATUS": 10, "STATE": 11,
             "ERROR_CODE": 12, "RECIPE_ID": 13, "TRIGGER_COUNT": 14, "INSPECTION_ID": 15,
             "DECISION": 17, "MODEL_ID": 18, "X": 19, "Y": 21, "YAW": 23, "BIN": 24, "SCORE": 25,
             "DURATION": 26, "QUEUED": 27, "RESULT_TRIGGER": 28}  # fmt: skip
#: Registers the PLC writes, and the whole block's size.
N_CONTROL = 3
N_REGISTERS = 29
STATUS_AT = REGISTERS["STATUS"]


def _u32(v: int) -> list[int]:
    v &= 0xFFFFFFFF
    return [v >> 16, v & 0xFFFF]


def _i32(v: float | None, scale: float) -> list[int]:
    if v is None or not math.isfinite(v):
        return _u32(-(2**31))
    return _u32(max(-(2**31) + 1, min(2**31 - 1, round(v * scale))))


def encode(snap: Snapshot) -> list[int]:
    """The read-only registers 10..28 of a snapshot (see the module docstring)."""
    bits = {
        "ONLINE": True, "TRIGGER_READY": snap.trigger_ready, "TRIGGER_ACK": snap.trigger_ack,
        "BUSY": snap.busy, "RESULTS_VALID": snap.results_valid, "ERROR": int(snap.error) != 0,
        "ESTOP": snap.estop, "RUNNING": snap.running, "RESULTS_OVERFLOW": snap.overflows > 0,
        "TRIGGER_ENABLED": snap.trigger_enabled,
    }  # fmt: skip
    status = sum(1 << STATUS_BITS[k] for k, on in bits.items() if on)
    r = snap.result
    words = [status, int(snap.state), int(snap.error), snap.recipe & 0xFFFF, snap.triggers & 0xFFFF]
    if r is None:
        words += [0, 0, 0, 0, *_i32(None, 1), *_i32(None, 1), 0x8000, 0, 0, 0]
    else:
        yaw = 0x8000 if r.yaw_rad is None else round(math.degrees(r.yaw_rad) * 100) & 0xFFFF
        score = 0 if r.score is None else max(0, min(1000, round(r.score * 1000)))
        words += [*_u32(r.inspection_id), r.decision_code, r.model_id & 0xFFFF,
                  *_i32(r.x_m, 1e5), *_i32(r.y_m, 1e5), yaw, r.bin & 0xFFFF, score,
                  min(65535, round(r.duration_s * 1000))]  # fmt: skip
    words += [snap.queued & 0xFFFF, 0 if r is None else r.trigger & 0xFFFF]
    assert len(words) == N_REGISTERS - STATUS_AT
    return words


def decode_result(regs: list[int]) -> dict[str, Any]:
    """The result words of registers 10..28 (as read by a PLC), in SI units (for the
    simulated PLC and the tests)."""

    def s32(hi: int, lo: int) -> int | None:
        v = (hi << 16) | lo
        return None if v == 0x80000000 else (v - (1 << 32) if v & 0x80000000 else v)

    base = STATUS_AT
    at = {k: v - base for k, v in REGISTERS.items() if v >= base}
    x = s32(regs[at["X"]], regs[at["X"] + 1])
    y = s32(regs[at["Y"]], regs[at["Y"] + 1])
    yaw = regs[at["YAW"]]
    return {
        "status": regs[at["STATUS"]],
        "state": regs[at["STATE"]],
        "error": regs[at["ERROR_CODE"]],
        "recipe": regs[at["RECIPE_ID"]],
        "triggers": regs[at["TRIGGER_COUNT"]],
        "inspection_id": (regs[at["INSPECTION_ID"]] << 16) | regs[at["INSPECTION_ID"] + 1],
        "decision": regs[at["DECISION"]],
        "model_id": regs[at["MODEL_ID"]],
        "x_m": None if x is None else x / 1e5,
        "y_m": None if y is None else y / 1e5,
        "yaw_rad": None
        if yaw == 0x8000
        else math.radians((yaw - 65536 if yaw & 0x8000 else yaw) / 100),
        "bin": regs[at["BIN"]],
        "score": regs[at["SCORE"]] / 1000,
        "duration_s": regs[at["DURATION"]] / 1000,
        "queued": regs[at["QUEUED"]],
        "result_trigger": regs[at["RESULT_TRIGGER"]],
    }


def _bit(word: int, name: str) -> bool:
    return bool(word >> CONTROL_BITS[name] & 1)


#: Most Modbus TCP connections served at once (a line has one PLC, perhaps an HMI and a
#: diagnostic tool; Modbus has no sign-in, so the count is the only bound on clients).
MAX_CLIENTS = 16


def _capped_server(base: type, max_clients: int) -> type:
    """``base`` (pymodbus's TCP server) refusing connections beyond ``max_clients``: the
    extra one is closed as soon as it is made and forgotten."""

    class CappedServer(base):
        def callback_new_connection(self) -> Any:
            handler = super().callback_new_connection()
            if len(self.active_connections) < max_clients:
                return handler
            server = self

            def refuse(transport: Any) -> None:
                server.active_connections.pop(handler.unique_id, None)
                log.warning("Modbus TCP: %d connections already: one more refused", max_clients)
                transport.close()

            handler.connection_made = refuse
            handler.connection_lost = lambda exc: None
            return handler

    return CappedServer


class ModbusLink:
    """The Modbus TCP server over one :class:`Handshake` (on the cell's event loop).

    Parameters
    ----------
    handshake : Handshake
    host, port : str, int
        Where to listen.
    role : Role
        The role every Modbus client acts with (Modbus has no sign-in).
    max_clients : int
        Connections served at once (1..:data:`MAX_CLIENTS`); one more is closed as it
        arrives, so a client that opens connections in a loop cannot exhaust the cell.
    """

    def __init__(self, handshake: Handshake, *, host: str, port: int, role: Role,
                 max_clients: int = MAX_CLIENTS) -> None:  # fmt: skip
        if (
            isinstance(max_clients, bool)
            or not isinstance(max_clients, int)
            or not (1 <= max_clients <= MAX_CLIENTS)
        ):
            raise ValueError(
                f"max_clients must be an integer in 1..{MAX_CLIENTS}, got {max_clients!r}"
            )
        self.max_clients = max_clients
        self.handshake = handshake
        self.host = host
        self.port = port
        self.user = LinkUser("modbus", role)
        self._server: Any = None
        self._task: Any = None

    async def start(self) -> None:
        """Listen (raises ``RuntimeError`` when the address cannot be bound)."""
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        blocks = [
            SimData(0, count=N_CONTROL, values=0, datatype=DataType.REGISTERS),
            SimData(N_CONTROL, count=N_REGISTERS - N_CONTROL, values=0,
                    datatype=DataType.REGISTERS, readonly=True),
        ]  # fmt: skip
        device = SimDevice(0, simdata=blocks, action=self._action)
        self._server = _capped_server(ModbusTcpServer, self.max_clients)(
            device, address=(self.host, self.port)
        )
        await self._server.serve_forever(background=True)
        log.info("Modbus TCP server listening on %s:%d (acting as %s)", self.host, self.port,
                 self.user.role.name)  # fmt: skip

    async def stop(self) -> None:
        """Stop listening and close the clients' connections."""
        if self._server is not None:
            with contextlib.suppress(Exception):
                await self._server.shutdown()
            self._server = None

    async def _action(self, func_code: int, start: int, address: int, count: int,
                      registers: list[int], values: list[int] | list[bool] | None) -> Any:  # fmt: skip
        """Every request: refresh the status words; a write to the control registers is
        the PLC's command (edges of CONTROL, taken before the write lands)."""
        if values and address < N_CONTROL:
            new = list(registers[:N_CONTROL])
            for i, v in enumerate(values):
                if address + i < N_CONTROL:
                    new[address + i] = int(v) & 0xFFFF
            await self._command(registers[0], new)
        registers[STATUS_AT - start : N_REGISTERS - start] = encode(self.handshake.snapshot)
        return None

    async def _command(self, old_control: int, regs: list[int]) -> None:
        hs, user = self.handshake, self.user
        new = regs[0]
        if int(user.role) < int(Role.operator):
            if new != old_control:  # a viewer's link reads; every command is refused
                hs._fail(ErrorCode.ROLE_TOO_LOW, f"Modbus acts as {user.role.name}: read only")
            return

        def rose(name: str) -> bool:
            return _bit(new, name) and not _bit(old_control, name)

        def fell(name: str) -> bool:
            return _bit(old_control, name) and not _bit(new, name)

        if _bit(new, "TRIGGER_ENABLE") != hs.snapshot.trigger_enabled:
            hs.set_trigger_enable(_bit(new, "TRIGGER_ENABLE"))
        if rose("RESET"):
            await hs.reset(user)
        if rose("RESULTS_ACK"):
            hs.acknowledge()
        if fell("RESULTS_ACK"):
            hs.present_next()
        if rose("RECIPE_SELECT"):
            await hs.select_recipe(user, regs[1])
        if rose("RUN"):
            await hs.start_run(user, regs[2] or None)
        if fell("RUN") and hs.snapshot.running:
            hs.stop_run(user)
        if rose("TRIGGER"):
            await hs.trigger(user)
        if fell("TRIGGER"):
            hs.clear_trigger()
