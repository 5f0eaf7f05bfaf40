"""Duplicate detection: a repeated sequence number is answered from the cache, not run again."""

import numpy as np

from robot.drivers.serial import frames as fr
from robot.model import ASEA

SESSION = "0BADCAFE"


async def hello(host, seq, session=SESSION):
    host.send(fr.Hello(seq, session))
    reply = await host.reply(seq)
    assert isinstance(reply, fr.Ack)
    return fr.HelloInfo.from_args(reply.args)


async def test_resent_move_with_the_same_seq_runs_once(raw_host, emulator):
    info = await hello(raw_host, 1)
    assert not info.resumed and info.cache_depth == 64 and info.window == 8
    move = fr.MoveJoints(2, 1, tuple(ASEA.q_ready), speed=1.0)
    first = raw_host.send(move)
    raw_host.send(move)  # e.g. the host's reply timer fired before the answer came
    await raw_host.reply(2)
    await raw_host.quiet(0.1)
    raw_host.send(move)  # and once more after the answer: served from the cache
    await raw_host.reply(2, count=2)
    assert first  # the bytes were identical each time
    replies = raw_host.replies(2)
    assert len(replies) == 2 and replies[0] == replies[1]
    assert isinstance(replies[0], fr.Ack) and replies[0].verb == "MOVE"
    assert emulator.executed_mids() == [1]
    assert emulator.stats.duplicates == 2


async def test_a_move_id_runs_once_whatever_the_sequence_number(raw_host, emulator):
    await hello(raw_host, 1)
    raw_host.send(fr.MoveJoints(2, 5, tuple(ASEA.q_ready), speed=1.0))
    await raw_host.reply(2)
    raw_host.send(fr.MoveJoints(3, 5, tuple(ASEA.q_home), speed=1.0))  # same mid, new seq
    again = await raw_host.reply(3)
    assert isinstance(again, fr.Ack)
    assert fr.MoveOutcome.from_args(again.args).mid == 5
    assert emulator.executed_mids() == [5]


async def test_resent_run_of_a_streamed_trajectory_runs_once(raw_host, emulator):
    await hello(raw_host, 10)
    q0 = tuple(ASEA.q_home)
    raw_host.send(fr.TrajBegin(11, 1, 2))
    raw_host.send(fr.TrajPoint(12, 1, 0, 0.0, q0, (0.0,) * 5))
    raw_host.send(fr.TrajPoint(13, 1, 1, 0.5, q0, (0.0,) * 5))
    raw_host.send(fr.TrajPoint(13, 1, 1, 0.5, q0, (0.0,) * 5))  # duplicate point
    raw_host.send(fr.Run(14, 1))
    raw_host.send(fr.Run(14, 1))
    await raw_host.reply(14, count=1)
    await raw_host.quiet(0.1)
    assert len(raw_host.replies(13)) == 1  # the duplicate arrived while pending: one reply
    raw_host.send(fr.Run(15, 1))  # a new number for the same move: reported, not re-run
    status = fr.MoveOutcome.from_args((await raw_host.reply(15)).args)
    assert status.mid == 1
    assert emulator.executed_mids() == [1]


async def test_session_resume_keeps_the_cache_and_a_new_session_makes_old_seqs_stale(
    raw_host, emulator
):
    await hello(raw_host, 1)
    move = fr.MoveJoints(2, 1, tuple(ASEA.q_ready), speed=1.0)
    raw_host.send(move)
    original = await raw_host.reply(2)
    info = await hello(raw_host, 3)  # the same session id: a reconnecting host
    assert info.resumed
    raw_host.send(move)
    assert await raw_host.reply(2, count=2) == original
    other = await hello(raw_host, 4, session="12345678")  # a different host
    assert not other.resumed and other.boot_id == info.boot_id
    raw_host.send(move)  # its seq is older than the new session's HELLO
    stale = await raw_host.reply(2, count=3)
    assert isinstance(stale, fr.Nak) and stale.code == "STALE"
    assert emulator.executed_mids() == [1]


async def test_commands_before_hello_are_refused_but_estop_is_obeyed(raw_host, emulator):
    raw_host.send(fr.Ping(1))
    nak = await raw_host.reply(1)
    assert isinstance(nak, fr.Nak) and nak.code == "NOSESSION"
    raw_host.send(fr.EStop(2))
    ack = await raw_host.reply(2)
    assert isinstance(ack, fr.Ack) and ack.verb == "ESTOP"
    assert emulator.driver.state.estopped


async def test_seq_far_behind_the_window_is_stale_not_executed(raw_host, emulator):
    await hello(raw_host, 1)
    for s in range(2, 80):
        raw_host.send(fr.Ping(s))
        await raw_host.reply(s)
    raw_host.send(fr.MoveJoints(5, 1, tuple(ASEA.q_ready), speed=1.0))  # never seen, too old
    nak = await raw_host.reply(5, count=2)
    assert isinstance(nak, fr.Nak) and nak.code == "STALE"
    assert emulator.executions == []
    np.testing.assert_allclose(emulator.driver.state.q, ASEA.q_home)


async def test_driver_resends_through_lost_replies_without_running_twice(driver, emulator):
    from robot.drivers.serial import FaultConfig

    emulator.fault = FaultConfig(drop_p=0.3, directions="tx")  # replies and events get lost
    for goal in (ASEA.q_ready, ASEA.q_home, ASEA.q_ready):
        report = await driver.move_joints(goal, speed=1.0)
        assert report.completed
    emulator.fault = FaultConfig()
    assert emulator.executed_mids() == [1, 2, 3]
    assert driver.stats["resends"] > 0 and emulator.stats.duplicates > 0
