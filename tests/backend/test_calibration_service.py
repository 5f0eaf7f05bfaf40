"""Calibration sessions in the database: samples kept with their reasons, re-solve gives
the same answer, one active calibration per kind, history, nothing left behind on failure."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import func, select

from backend import calibration as svc
from backend.db.models import Calibration, CalibrationKind, CalibrationSample
from backend.db.models import Cell as CellRow
from backend.db.session import Database
from tests.utils.calibration import TRUE_T_EE_CAM, rotation_error_deg, translation_error_mm
from vision.calibration import Chessboard, HandEyeOptions, IntrinsicsOptions
from vision.calibration.io import read_gray
from vision.errors import CalibrationError


@pytest.fixture
async def db(settings):
    database = Database(settings.database_url)
    async with database.session() as s:
        s.add(CellRow(name="cell-1"))
    yield database
    await database.dispose()


def _samples(folder, *, with_poses=True, names=None):
    from vision.calibration.io import read_poses

    poses = read_poses(folder.poses_file)
    return [
        svc.SampleIn(
            name=f.name,
            image=read_gray(f),
            joints=[0.1 * k, 1.0, -1.0, 0.0, 0.0],
            T_base_ee=poses[k] if with_poses else None,
        )
        for k, f in enumerate(folder.files)
    ]


async def _session(db, kind, folder, **kw):
    async with db.session() as s:
        cell_id = await svc.cell_id_of(s, "cell-1")
        row = await svc.create_session(s, kind=kind, board=folder.data.board, cell_id=cell_id)
        await svc.add_samples(s, row, _samples(folder, **kw))
        return row.id


async def _count(db, model) -> int:
    async with db.session() as s:
        return int(await s.scalar(select(func.count()).select_from(model)))


async def test_samples_are_kept_with_image_pose_corners_and_reason(db, synthetic_folder):
    sid = await _session(db, CalibrationKind.hand_eye, synthetic_folder)
    async with db.session() as s:
        row = await svc.get_session(s, sid)
        samples = sorted(row.samples, key=lambda x: x.index)
        assert [x.index for x in samples] == list(range(9))
        assert [x.accepted for x in samples] == [True] * 8 + [False]
        assert samples[0].reason == "54 corners (sb detector)" and len(samples[0].corners) == 54
        assert samples[-1].name == "view_08.png"
        assert samples[-1].reason == "no 9x6 chessboard found (sector-based and classic detectors)"
        assert samples[-1].corners is None
        assert samples[0].image_png[:4] == b"\x89PNG" and samples[0].joints[1] == 1.0
        np.testing.assert_allclose(
            samples[2].T_base_ee, synthetic_folder.data.T_base_ee[2], atol=1e-9
        )
        summary = svc.session_summary(row)
        assert summary["status"] == "collecting" and summary["accepted_count"] == 8


async def test_hand_eye_session_needs_a_pose_per_image_and_keeps_nothing_otherwise(
    db, synthetic_folder
):
    async with db.session() as s:
        row = await svc.create_session(
            s,
            kind=CalibrationKind.hand_eye,
            board=synthetic_folder.data.board,
            cell_id=await svc.cell_id_of(s, "cell-1"),
        )
    with pytest.raises(ValueError, match=r"sample 'view_00\.png' has no robot pose"):
        async with db.session() as s:
            row = await svc.get_session(s, row.id)
            await svc.add_samples(s, row, _samples(synthetic_folder, with_poses=False))
    assert await _count(db, CalibrationSample) == 0


async def test_re_solve_gives_the_same_answer_and_other_options_another(db, synthetic_folder):
    sid = await _session(db, CalibrationKind.intrinsic, synthetic_folder)
    async with db.session() as s:
        first = (await svc.solve_session(s, sid)).calibration
    async with db.session() as s:
        again = (await svc.solve_session(s, sid)).calibration
    async with db.session() as s:
        radial = (
            await svc.solve_session(
                s, sid, svc.SolveOptions(intrinsics=IntrinsicsOptions(radial_only=True))
            )
        ).calibration
    assert first.id != again.id
    assert again.parameters == first.parameters and again.residuals == first.residuals
    assert again.rms_px == first.rms_px
    assert radial.parameters["dist"][2:4] == [0.0, 0.0] and radial.parameters != first.parameters
    assert first.options["intrinsics"]["radial_only"] is False
    assert radial.options["intrinsics"]["radial_only"] is True
    assert first.sample_count == 8
    rejected = first.residuals["rejected"]
    assert [(r["name"], r["reason"].split(" (")[0]) for r in rejected] == [
        ("view_08.png", "no 9x6 chessboard found")
    ]
    async with db.session() as s:
        hist = await svc.history(s, session_id=sid)
        assert [c.id for c in hist] == [radial.id, again.id, first.id]
        assert not any(c.active for c in hist)


async def test_one_active_calibration_per_kind(db, synthetic_folder):
    sid = await _session(db, CalibrationKind.intrinsic, synthetic_folder)
    async with db.session() as s:
        a = (await svc.solve_session(s, sid, svc.SolveOptions(activate=True))).calibration
        b = (await svc.solve_session(s, sid)).calibration
    assert a.active and not b.active
    async with db.session() as s:
        await svc.activate(s, b.id)
    async with db.session() as s:
        act = await svc.active_calibrations(s, await svc.cell_id_of(s, "cell-1"))
        assert act[CalibrationKind.intrinsic].id == b.id and act[CalibrationKind.hand_eye] is None
        cam = await svc.active_camera_calibration(s, await svc.cell_id_of(s, "cell-1"))
        assert cam.intrinsic_id == b.id and cam.T_ee_cam is None and cam.hand_eye_id is None
        assert not (await svc.get_calibration(s, a.id)).active
        row = await svc.get_session(s, sid)
        assert svc.session_summary(row)["status"] == "active"


async def test_hand_eye_solve_stores_both_and_activation_brings_its_intrinsics(
    db, synthetic_folder
):
    sid = await _session(db, CalibrationKind.hand_eye, synthetic_folder)
    async with db.session() as s:
        out = await svc.solve_session(s, sid, svc.SolveOptions(activate=True))
    he, intr = out.calibration, out.intrinsic
    assert he.kind is CalibrationKind.hand_eye and intr is not None
    assert he.parameters["intrinsics_id"] == intr.id
    X = np.asarray(he.parameters["T_ee_cam"])
    assert (
        translation_error_mm(X, TRUE_T_EE_CAM) < 1.0 and rotation_error_deg(X, TRUE_T_EE_CAM) < 0.2
    )
    async with db.session() as s:
        act = await svc.active_calibrations(s, await svc.cell_id_of(s, "cell-1"))
        assert (
            act[CalibrationKind.hand_eye].id == he.id
            and act[CalibrationKind.intrinsic].id == intr.id
        )
        # Solve again against the now active intrinsics: same samples, same answer each time.
        opts = svc.SolveOptions(
            intrinsics_source="active", hand_eye=HandEyeOptions(methods=("park",))
        )
        one = (await svc.solve_session(s, sid, opts)).calibration
        two = (await svc.solve_session(s, sid, opts)).calibration
        assert one.parameters == two.parameters and one.parameters["intrinsics_id"] == intr.id
        report = svc.calibration_report(one)
        assert report["summary"]["method"] == "park" and "consistency" in report["plots"]
        for plot in svc.PLOTS:
            assert svc.report_png(one, plot)[:4] == b"\x89PNG"


async def test_failed_solve_leaves_nothing_behind(db, synthetic_folder):
    sid = await _session(db, CalibrationKind.intrinsic, synthetic_folder)
    before = await _count(db, Calibration)
    with pytest.raises(
        CalibrationError,
        match=r"need at least 20 images with the board, the session has 8 of 9 \(rejected: view_08.png: no 9x6",
    ):
        async with db.session() as s:
            await svc.solve_session(
                s, sid, svc.SolveOptions(intrinsics=IntrinsicsOptions(min_views=20), activate=True)
            )
    assert await _count(db, Calibration) == before
    with pytest.raises(CalibrationError, match="the cell has no active intrinsic calibration"):
        async with db.session() as s:
            hid = await _session(db, CalibrationKind.hand_eye, synthetic_folder)
            await svc.solve_session(s, hid, svc.SolveOptions(intrinsics_source="active"))
    assert await _count(db, Calibration) == before


async def test_unknown_ids_and_bad_boards(db):
    async with db.session() as s:
        with pytest.raises(svc.NotFound, match="no calibration session with id 99"):
            await svc.get_session(s, 99)
        with pytest.raises(svc.NotFound, match="no calibration with id 7"):
            await svc.activate(s, 7)
        with pytest.raises(ValueError, match="has no unique frame"):
            await svc.create_session(
                s, kind=CalibrationKind.hand_eye, board=Chessboard(8, 6, 0.02), cell_id=1
            )
