"""The handshake's result queue and E-STOP, on the cell's real event bus: results are
presented one at a time in order, each inspection once; beyond the queue the newest are
counted as overflow (error 7) and nothing presented is lost; the E-STOP event drops
Trigger Ready at once."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

from backend.cell.events import CellStopped, EventBus
from backend.plc.handshake import ErrorCode, Handshake, PlcResult, SystemState


def _result(iid: int) -> PlcResult:
    return PlcResult(inspection_id=iid, decision="recognized", model="m", model_id=1, score=0.5,
                     x_m=0.8, y_m=0.0, yaw_rad=0.0, bin=0, bin_name=None, duration_s=0.1,
                     trigger=0)  # fmt: skip


def _runtime() -> SimpleNamespace:
    return SimpleNamespace(bus=EventBus(), cell=SimpleNamespace(estopped=False), sim=None)


def test_results_queue_in_order_once_each_and_overflow_is_counted() -> None:
    async def main() -> list[int]:
        hs = Handshake(_runtime(), name="test", max_queue=3)
        await hs.start()
        seen: list[int] = []
        try:
            for iid in (1, 2, 2, 3, 4, 5, 6):  # 2 twice: offered once
                hs._offer(_result(iid))
            s = hs.snapshot
            assert s.results_valid and s.result is not None and s.result.inspection_id == 1
            assert s.queued == 3 and s.overflows == 2 and s.error is ErrorCode.RESULTS_OVERFLOW
            while hs.snapshot.results_valid:
                assert hs.snapshot.result is not None
                seen.append(hs.snapshot.result.inspection_id)
                assert hs.acknowledge(seen[-1])
                assert not hs.snapshot.results_valid  # Results Valid drops with the ack
                hs.present_next()
            assert not hs.acknowledge()  # nothing presented: nothing to take
        finally:
            await hs.stop()
        return seen

    assert asyncio.run(main()) == [1, 2, 3, 4]


def test_acknowledging_another_id_takes_nothing() -> None:
    async def main() -> None:
        hs = Handshake(_runtime(), name="test")
        await hs.start()
        try:
            hs._offer(_result(7))
            assert not hs.acknowledge(8) and hs.snapshot.results_valid
            assert hs.acknowledge(7) and not hs.snapshot.results_valid
        finally:
            await hs.stop()

    asyncio.run(main())


def test_estop_event_drops_trigger_ready_at_once() -> None:
    async def main() -> None:
        rt = _runtime()
        hs = Handshake(rt, name="test")
        await hs.start()
        states: list[SystemState] = []
        hs.add_listener(lambda s: states.append(s.state))
        try:
            hs.set_trigger_enable(True)
            assert hs.snapshot.trigger_ready and hs.snapshot.state is SystemState.READY
            rt.bus.publish(CellStopped(active=True))  # synchronously, no loop turn needed
            assert hs.snapshot.estop and not hs.snapshot.trigger_ready
            assert hs.snapshot.state is SystemState.ESTOP and states[-1] is SystemState.ESTOP
            rt.bus.publish(CellStopped(active=False))
            assert hs.snapshot.state is SystemState.READY
        finally:
            await hs.stop()

    asyncio.run(main())
