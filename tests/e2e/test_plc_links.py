"""The PLC links as a line's PLC meets them: ``visioncell serve`` (a subprocess) with its OPC UA
and Modbus TCP servers on loopback, driven with the real clients (asyncua's, pymodbus's).

Every edge of the handshake: trigger, result, acknowledge; a trigger while busy, a result
not acknowledged, E-STOP seen and reset; wrong credentials and a role too low refused; a
continuous run's results each seen once; recipe selection.  The cell runs the ideal arm and
a folder camera replaying one COIL-20 image, so inspections are short and all say obj2."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator

import httpx
import pytest

from backend.plc.handshake import ErrorCode, SystemState
from backend.plc.modbus import REGISTERS
from backend.plc.simplc import ModbusPlc, OpcUaPlc
from tests.utils.plccell import TIMEOUT_S, PlcCell, start_plc_cell

pytestmark = [pytest.mark.e2e, pytest.mark.slow, pytest.mark.timeout(1800)]

BOUND_S = 300.0  # a hang's bound on a loaded machine, never a timing requirement


@pytest.fixture(scope="module")
def cell(tmp_path_factory, data_dir) -> Iterator[PlcCell]:
    c = start_plc_cell(tmp_path_factory.mktemp("plc"), data_dir)
    yield c
    c.server.stop()


def _rest(cell: PlcCell, method: str, path: str, role: str = "operator", **kw) -> httpx.Response:
    return httpx.request(method, cell.server.base + path, headers=cell.headers(role),
                         timeout=TIMEOUT_S, **kw)  # fmt: skip


def _modbus(cell: PlcCell) -> ModbusPlc:
    assert cell.modbus_port is not None
    return ModbusPlc("127.0.0.1", cell.modbus_port, bound_s=BOUND_S)


def _opcua(cell: PlcCell, role: str = "operator", *, password: str | None = None) -> OpcUaPlc:
    assert cell.opcua_url is not None
    return OpcUaPlc(cell.opcua_url, user=f"plc-{role}",
                    password=cell.tokens[role] if password is None else password, bound_s=BOUND_S)  # fmt: skip


async def _idle_modbus(plc: ModbusPlc) -> None:
    """Leave the Modbus handshake clean: no bits set, nothing queued, no error."""
    await plc.set_bits(TRIGGER=False, RUN=False, RESULTS_ACK=False, RECIPE_SELECT=False)
    while True:
        w = await plc.wait(lambda w: "BUSY" not in w["flags"], "idle")
        if "RESULTS_VALID" not in w["flags"]:
            break
        await plc.acknowledge()
    await plc.set_bits(RESET=True)
    await plc.set_bits(RESET=False)


def test_modbus_trigger_result_acknowledge(cell: PlcCell) -> None:
    async def main() -> list:
        plc = _modbus(cell)
        await plc.connect()
        try:
            w = await plc.read()
            assert "ONLINE" in w["flags"] and "TRIGGER_READY" not in w["flags"]  # not enabled
            got = [await plc.trigger() for _ in range(3)]
            w = await plc.read()
            assert "TRIGGER_READY" in w["flags"] and w["state"] == SystemState.READY
            return got
        finally:
            plc.close()

    got = asyncio.run(main())
    ids = [t.result["inspection_id"] for t in got]
    assert len(set(ids)) == 3 and ids == sorted(ids)
    for t in got:  # the words are the stored row's
        row = _rest(cell, "GET", f"/api/inspections/{t.result['inspection_id']}", "viewer").json()
        assert row["decision"] == "recognized" and row["model"] == "obj2"
        assert t.result["decision"] == 1 and t.result["model_id"] == cell.model_ids["obj2"]
        assert t.result["score"] == pytest.approx(row["score"], abs=1e-3)
    assert [t.result["result_trigger"] for t in got] == sorted(
        t.result["result_trigger"] for t in got
    )


def test_modbus_result_not_acknowledged_holds_the_next_trigger(cell: PlcCell) -> None:
    async def main() -> None:
        plc = _modbus(cell)
        await plc.connect()
        try:
            await plc.set_bits(TRIGGER_ENABLE=True)
            await plc.wait(lambda w: "TRIGGER_READY" in w["flags"], "ready")
            await plc.set_bits(TRIGGER=True)
            await plc.set_bits(TRIGGER=False)
            w = await plc.wait(lambda w: "RESULTS_VALID" in w["flags"], "result")
            first = w["inspection_id"]
            assert "TRIGGER_READY" not in w["flags"]  # the result waits for its ack
            before = w["triggers"]
            await plc.set_bits(TRIGGER=True)  # ... so this trigger is refused
            w = await plc.read()
            assert w["error"] == ErrorCode.RESULT_NOT_ACKNOWLEDGED and "ERROR" in w["flags"]
            assert w["triggers"] == before and "TRIGGER_ACK" not in w["flags"]
            assert w["inspection_id"] == first and "RESULTS_VALID" in w["flags"]  # kept
            await plc.set_bits(TRIGGER=False)
            await plc.acknowledge()
            w = await plc.wait(lambda w: "TRIGGER_READY" in w["flags"], "ready after ack")
            t = await plc.trigger()  # and the next trigger is taken
            assert t.result["inspection_id"] > first
        finally:
            await _idle_modbus(plc)
            plc.close()

    asyncio.run(main())


def test_modbus_trigger_while_busy_and_a_run(cell: PlcCell) -> None:
    """A run of 4 objects started by the RUN bit: a trigger meanwhile is refused (busy);
    each of the run's results is presented once, in order, acknowledged one by one."""

    async def main() -> list[int]:
        plc = _modbus(cell)
        await plc.connect()
        try:
            await plc.set_bits(TRIGGER_ENABLE=True)
            await plc.write(REGISTERS["RUN_COUNT"], 4)
            await plc.set_bits(RUN=True)
            w = await plc.wait(lambda w: "RUNNING" in w["flags"], "running")
            assert "BUSY" in w["flags"] and "TRIGGER_READY" not in w["flags"]
            await plc.set_bits(TRIGGER=True)
            w = await plc.read()
            assert w["error"] == ErrorCode.TRIGGER_WHILE_BUSY and "TRIGGER_ACK" not in w["flags"]
            await plc.set_bits(TRIGGER=False)
            ids: list[int] = []
            while len(ids) < 4:
                w = await plc.wait(lambda w: "RESULTS_VALID" in w["flags"], "a run's result")
                ids.append(w["inspection_id"])
                assert w["result_trigger"] == 0  # a run's, not a trigger's
                await plc.acknowledge()
            await plc.wait(lambda w: "RUNNING" not in w["flags"], "the run's end")
            w = await plc.read()
            assert "RESULTS_VALID" not in w["flags"] and w["queued"] == 0
            return ids
        finally:
            await _idle_modbus(plc)
            plc.close()

    ids = asyncio.run(main())
    assert len(set(ids)) == 4 and ids == sorted(ids)
    rows = _rest(cell, "GET", "/api/inspections?limit=4", "viewer").json()["data"]
    assert sorted(r["id"] for r in rows) == ids  # the run's four rows, each seen once


def test_modbus_estop_bit_and_reset(cell: PlcCell) -> None:
    async def main() -> None:
        plc = _modbus(cell)
        await plc.connect()
        try:
            await plc.set_bits(TRIGGER_ENABLE=True)
            await plc.wait(lambda w: "TRIGGER_READY" in w["flags"], "ready")
            r = await asyncio.to_thread(_rest, cell, "POST", "/api/robot/estop")
            assert r.status_code == 200, r.text
            w = await plc.wait(lambda w: "ESTOP" in w["flags"], "the E-STOP bit")
            assert w["state"] == SystemState.ESTOP and "TRIGGER_READY" not in w["flags"]
            await plc.set_bits(TRIGGER=True)
            w = await plc.read()
            assert w["error"] == ErrorCode.ESTOP
            await plc.set_bits(TRIGGER=False)
            await plc.set_bits(RESET=True)  # an operator's reset, as the REST one
            await plc.set_bits(RESET=False)
            w = await plc.wait(lambda w: "ESTOP" not in w["flags"], "the reset")
            assert w["error"] == 0
            state = (await asyncio.to_thread(_rest, cell, "GET", "/api/robot/state")).json()
            assert state["state"]["estopped"] is False
        finally:
            await _idle_modbus(plc)
            plc.close()

    asyncio.run(main())


def test_modbus_refuses_writes_to_the_status(cell: PlcCell) -> None:
    async def main() -> None:
        plc = _modbus(cell)
        await plc.connect()
        try:
            rr = await plc.write(REGISTERS["STATUS"], 0xFFFF)
            assert rr.isError()  # illegal address: the status is the cell's
            rr = await plc.write(REGISTERS["INSPECTION_ID"], 7)
            assert rr.isError()
            w = await plc.read()
            assert w["status"] != 0xFFFF and "ONLINE" in w["flags"]
        finally:
            await _idle_modbus(plc)
            plc.close()

    asyncio.run(main())


def test_read_only_links_refuse_every_command(tmp_path) -> None:
    """``VISIONCELL_MODBUS_ROLE=viewer``: the PLC reads the state; a trigger, a run, a
    recipe selection are refused with error 10 (role too low) and start nothing.
    ``VISIONCELL_OPCUA_ANONYMOUS=read-only``: a client without a user reads and subscribes,
    and may call no method.  A user certificate signs its user in.  Failed OPC UA sign-ins
    block the address as REST's do."""
    from asyncua import ua
    from asyncua.ua.uaerrors import UaError

    from tests.e2e.conftest import start_server
    from tests.utils.factories import free_port
    from tests.utils.plccell import _wait_listening

    port, opc_port = free_port(), free_port()
    url = f"opc.tcp://127.0.0.1:{opc_port}/visioncell"
    certs = tmp_path / "user-certs"
    certs.mkdir()
    server = start_server(tmp_path, VISIONCELL_MODBUS_PORT=str(port), VISIONCELL_MODBUS_ROLE="viewer",
                          VISIONCELL_OPCUA_ENDPOINT=url, VISIONCELL_OPCUA_ANONYMOUS="read-only",
                          VISIONCELL_OPCUA_USER_CERTIFICATES=str(certs),
                          VISIONCELL_OPCUA_NODESETS="false", VISIONCELL_VIEW3D_ENABLED="false")  # fmt: skip

    async def certificate_sign_in() -> str:
        """A certificate in the folder signs its user in (an operator: Reset is allowed);
        one that is not there is refused."""
        from backend.plc.simplc import make_client_certificate

        cert, key = await make_client_certificate(tmp_path / "pki", "line-plc")
        (certs / "line-plc.der").write_bytes(cert.read_bytes())
        stranger = await make_client_certificate(tmp_path / "pki", "stranger")
        plc = OpcUaPlc(url, user=None, password=None, bound_s=BOUND_S, certificate=stranger)
        with pytest.raises(UaError):
            await plc.connect()
        with contextlib.suppress(Exception):
            await plc.close()
        plc = OpcUaPlc(url, user=None, password=None, bound_s=BOUND_S, certificate=(cert, key))
        await plc.connect()
        try:
            await plc.call("Reset")  # an operator's method
            return str(await plc.nodes["CurrentState"].read_value())
        finally:
            await plc.close()

    async def anonymous() -> None:
        plc = OpcUaPlc(url, user=None, password=None, bound_s=BOUND_S)
        await plc.connect()
        try:
            await plc.wait(lambda v: "CurrentState" in v, "the state")
            assert await plc.nodes["Triggers"].read_value() == 0
            for name, args in (("Trigger", ()), ("Reset", ()),
                               ("StartRun", (ua.Variant(1, ua.VariantType.UInt32),))):  # fmt: skip
                with pytest.raises(UaError):
                    await plc.call(name, *args)
        finally:
            await plc.close()

    async def main() -> None:
        plc = ModbusPlc("127.0.0.1", port, bound_s=BOUND_S)
        await plc.connect()
        try:
            w = await plc.read()
            assert "ONLINE" in w["flags"] and w["error"] == 0
            for bits in ({"TRIGGER_ENABLE": True}, {"TRIGGER": True}, {"RUN": True},
                         {"RECIPE_SELECT": True}):  # fmt: skip
                await plc.set_bits(**bits)
                w = await plc.read()
                assert w["error"] == ErrorCode.ROLE_TOO_LOW, bits
                assert not w["flags"] & {"TRIGGER_ACK", "BUSY", "RUNNING", "TRIGGER_ENABLED"}
                await plc.set_bits(**{k: False for k in bits})
            assert w["triggers"] == 0
        finally:
            plc.close()

    async def throttled(token: str) -> None:
        for _ in range(5):  # VISIONCELL_SIGNIN_MAX_FAILURES's default
            plc = OpcUaPlc(url, user="reader", password="vc_" + "y" * 43, bound_s=BOUND_S)
            with pytest.raises(UaError):
                await plc.connect()
            with contextlib.suppress(Exception):
                await plc.close()
        plc = OpcUaPlc(url, user="reader", password=token, bound_s=BOUND_S)
        with pytest.raises(UaError):  # the address is blocked: even the right token
            await plc.connect()
        with contextlib.suppress(Exception):
            await plc.close()

    try:
        asyncio.run(main())
        _wait_listening(opc_port, server)
        asyncio.run(anonymous())
        server.token("line-plc", "operator")
        assert asyncio.run(certificate_sign_in()) in ("Idle", "Ready")
        asyncio.run(throttled(server.token("reader", "viewer")))
        assert "refused: too many failures" in server.log.read_text()
        jobs = httpx.get(
            f"{server.base}/api/jobs",
            timeout=TIMEOUT_S,
            headers={"Authorization": f"Bearer {server.token('v', 'viewer')}"},
        ).json()
        assert not [j for j in jobs["data"] if j["kind"].startswith("inspect")]
    finally:
        server.stop()


def test_opcua_wrong_credentials_are_refused(cell: PlcCell) -> None:
    from asyncua.ua.uaerrors import UaError

    async def refused(plc: OpcUaPlc) -> None:
        with pytest.raises((UaError, ConnectionError, OSError)):
            await plc.connect()
        with contextlib.suppress(Exception):
            await plc.close()

    async def main() -> None:
        assert cell.opcua_url is not None
        await refused(_opcua(cell, password="vc_" + "x" * 43))  # a token nobody holds
        # a live token of another user under this user's name
        await refused(_opcua(cell, "operator", password=cell.tokens["engineer"]))
        await refused(OpcUaPlc(cell.opcua_url, user=None, password=None, bound_s=BOUND_S))
        await refused(_opcua(cell, password="not a token"))

    asyncio.run(main())


def test_opcua_viewer_reads_and_may_not_trigger(cell: PlcCell) -> None:
    from asyncua import ua
    from asyncua.ua.uaerrors import BadUserAccessDenied

    async def main() -> None:
        plc = _opcua(cell, "viewer")
        await plc.connect()
        try:
            await plc.wait(lambda v: "CurrentState" in v, "the state")
            assert plc.values["CurrentState"] in ("Ready", "Idle")
            with pytest.raises(BadUserAccessDenied):
                await plc.call("Trigger")
            with pytest.raises(BadUserAccessDenied):
                await plc.call("StartRun", ua.Variant(1, ua.VariantType.UInt32))
            await plc.wait(lambda v: v.get("ErrorCode") == ErrorCode.ROLE_TOO_LOW, "the error code")
        finally:
            await plc.close()
        viewer = _opcua(cell, "viewer")
        await viewer.connect()
        try:
            with pytest.raises(BadUserAccessDenied):  # a changeover is an operator's
                await viewer.nodes["cell"].call_method(
                    viewer.nodes["SelectRecipe"], ua.Variant(1, ua.VariantType.UInt16)
                )
        finally:
            await viewer.close()
        op = _opcua(cell, "operator")
        await op.connect()
        try:
            await op.call("Reset")
        finally:
            await op.close()

    asyncio.run(main())


def test_opcua_trigger_result_acknowledge_estop_and_reset(cell: PlcCell) -> None:
    from asyncua.ua.uaerrors import BadInvalidState

    async def main() -> list:
        plc = _opcua(cell, "operator")
        await plc.connect()
        try:
            await plc.call("Reset")
            got = [await plc.trigger() for _ in range(3)]
            r = await asyncio.to_thread(_rest, cell, "POST", "/api/robot/estop")
            assert r.status_code == 200, r.text
            v = await plc.wait(lambda v: v.get("EStop") is True, "the E-STOP")
            assert v["CurrentState"] == "Stopped by E-STOP"
            with pytest.raises(BadInvalidState):
                await plc.call("Trigger")
            await plc.call("Reset")
            await plc.wait(lambda v: v.get("EStop") is False and v.get("CurrentState") == "Ready",
                           "the reset")  # fmt: skip
            got.append(await plc.trigger())
            return got
        finally:
            await plc.close()

    got = asyncio.run(main())
    ids = [t.result["inspection_id"] for t in got]
    assert len(set(ids)) == 4 and ids == sorted(ids)
    for t in got:
        row = _rest(cell, "GET", f"/api/inspections/{t.result['inspection_id']}", "viewer").json()
        assert (t.result["decision"], t.result["model"]) == (row["decision"], row["model"])
        assert t.result["model_id"] == cell.model_ids["obj2"]


def test_opcua_run_results_each_seen_once(cell: PlcCell) -> None:
    from asyncua import ua

    async def main() -> list[int]:
        plc = _opcua(cell, "operator")
        await plc.connect()
        try:
            await plc.call("StartRun", ua.Variant(5, ua.VariantType.UInt32))
            ids: list[int] = []
            while len(ids) < 5:
                await plc.wait(lambda v: v.get("ResultsValid") is True
                               and v.get("InspectionId") not in ids, "a run's result")  # fmt: skip
                res = await plc.read_result()
                ids.append(res["inspection_id"])
                assert await plc.acknowledge(res["inspection_id"])
            return ids
        finally:
            await plc.close()

    ids = asyncio.run(main())
    assert len(set(ids)) == 5 and ids == sorted(ids)


def test_recipe_changeover_over_both_links(cell: PlcCell) -> None:
    """Two recipes (made by an engineer over REST); a PLC selects them by number between two
    objects, over OPC UA (``SelectRecipe``) and Modbus (RECIPE_SELECT): the next result is
    inspected under the recipe selected, as its row says; an unknown number is refused with
    error 8 and changes nothing; a viewer may not select."""
    from asyncua import ua
    from asyncua.ua.uaerrors import BadInvalidState, BadUserAccessDenied

    ids = {}
    for number, policy in ((11, "top-only"), (12, "two-views")):
        r = _rest(cell, "POST", "/api/recipes", "engineer",
                  json={"name": f"line-{number}", "number": number, "policy": policy})  # fmt: skip
        assert r.status_code == 201, r.text
        ids[number] = r.json()["id"]

    async def main() -> list[tuple[int, int]]:
        out = []
        opc = _opcua(cell, "operator")
        await opc.connect()
        plc = _modbus(cell)
        await plc.connect()
        try:
            await opc.call("Reset")
            select = opc.nodes["SelectRecipe"]
            await opc.nodes["cell"].call_method(select, ua.Variant(11, ua.VariantType.UInt16))
            assert await opc.nodes["ActiveRecipeId"].read_value() == 11
            out.append((11, (await opc.trigger()).result["inspection_id"]))
            with pytest.raises(BadInvalidState):
                await opc.nodes["cell"].call_method(select, ua.Variant(99, ua.VariantType.UInt16))
            assert await opc.nodes["ErrorCode"].read_value() == ErrorCode.RECIPE_UNKNOWN
            assert await opc.nodes["ActiveRecipeId"].read_value() == 11
            await plc.write(REGISTERS["RECIPE_REQUEST"], 12)
            await plc.set_bits(RECIPE_SELECT=True)
            w = await plc.read()
            assert w["recipe"] == 12 and w["error"] == 0
            await plc.set_bits(RECIPE_SELECT=False)
            out.append((12, (await plc.trigger()).result["inspection_id"]))
        finally:
            await _idle_modbus(plc)
            plc.close()
            await opc.close()
        viewer = _opcua(cell, "viewer")
        await viewer.connect()
        try:
            with pytest.raises(BadUserAccessDenied):
                await viewer.nodes["cell"].call_method(
                    viewer.nodes["SelectRecipe"], ua.Variant(11, ua.VariantType.UInt16)
                )
        finally:
            await viewer.close()
        return out

    for number, iid in asyncio.run(main()):
        row = _rest(cell, "GET", f"/api/inspections/{iid}", "viewer").json()
        assert row["recipe_id"] == ids[number] and row["recipe"] == f"line-{number}", row
        assert row["policy"] == ("top-only" if number == 11 else "two-views")


def test_modbus_refusal_never_wedges_the_link(cell: PlcCell) -> None:
    """Refusals never leave a link wedged: after one, the next trigger is taken."""

    async def main() -> None:
        plc = _modbus(cell)
        await plc.connect()
        try:
            await plc.set_bits(TRIGGER_ENABLE=False)
            await plc.set_bits(TRIGGER=True)
            w = await plc.read()
            assert w["error"] == ErrorCode.TRIGGER_NOT_ENABLED
            await plc.set_bits(TRIGGER=False)
            t = await plc.trigger()
            assert t.result["decision"] == 1
        finally:
            await _idle_modbus(plc)
            plc.close()

    asyncio.run(main())


def test_opcua_result_events_one_per_result(cell: PlcCell) -> None:
    """An MES subscribed to the cell's InspectionResultEventType gets one event per result,
    with the result's id and words."""
    from backend.plc.opcua import NAMESPACE

    async def main() -> tuple[list, list]:
        plc = _opcua(cell, "operator")
        await plc.connect()
        events: list = []
        try:
            idx = await plc.client.get_namespace_index(NAMESPACE)
            etype = await plc.client.nodes.base_event_type.get_child(
                [f"{idx}:InspectionResultEventType"]
            )

            class Handler:
                def event_notification(self, event) -> None:
                    events.append(event)

            sub = await plc.client.create_subscription(10, Handler())
            await sub.subscribe_events(plc.nodes["cell"], etype)
            await plc.call("Reset")
            got = [await plc.trigger() for _ in range(2)]
            t0 = asyncio.get_running_loop().time()
            while len(events) < 2 and asyncio.get_running_loop().time() - t0 < BOUND_S:
                await asyncio.sleep(0.05)
            return got, events
        finally:
            await plc.close()

    got, events = asyncio.run(main())
    assert [e.InspectionId for e in events] == [t.result["inspection_id"] for t in got]
    for e, t in zip(events, got, strict=True):
        assert e.Decision == "recognized" and e.Model == "obj2"
        assert e.TriggerNumber == t.result["trigger"] and e.ModelId == cell.model_ids["obj2"]


def test_opcua_encrypted_channel(cell: PlcCell, tmp_path) -> None:
    """Over Basic256Sha256 SignAndEncrypt (offered by default beside None) the sign-in's
    token travels encrypted; the handshake is the same."""
    from backend.plc.simplc import make_client_certificate

    async def main():
        cert = await make_client_certificate(tmp_path / "pki")
        assert cell.opcua_url is not None
        plc = OpcUaPlc(cell.opcua_url, user="plc-operator", password=cell.tokens["operator"],
                       bound_s=BOUND_S, certificate=cert)  # fmt: skip
        await plc.connect()
        try:
            policy = plc.client.security_policy.URI
            return policy, await plc.trigger()
        finally:
            await plc.close()

    policy, t = asyncio.run(main())
    assert policy.endswith("#Basic256Sha256")
    assert t.result["decision"] == "recognized" and t.result["model"] == "obj2"
