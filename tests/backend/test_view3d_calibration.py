"""Frusta of an automatic calibration run in the 3D view: one per sample, cleared per run."""

from __future__ import annotations

import numpy as np
import viser

from backend.calibration.auto import CalibrationViewLog
from backend.view3d.calibviews import FOUND, MISSED, CalibrationFrusta
from tests.utils.factories import free_port


def test_frusta_follow_the_run():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        log = CalibrationViewLog()
        T = np.eye(4)
        T[:3, 3] = (0.5, -0.6, 0.9)
        log.add(T, True)  # a run already going when the view starts
        frusta = CalibrationFrusta(server, log, fov_rad=1.0, aspect=4 / 3)
        assert len(frusta.handles) == 1
        log.add(T, False)
        assert len(frusta.handles) == 2
        assert tuple(frusta.handles[1].color) == MISSED
        assert tuple(frusta.handles[0].color) == FOUND
        np.testing.assert_allclose(frusta.handles[0].position, T[:3, 3])
        log.clear()  # the next run replaces them
        assert frusta.handles == [] and log.poses == []
        log.add(T, True)
        assert len(frusta.handles) == 1
        frusta.close()
        log.add(T, True)
        assert len(frusta.handles) == 1  # no longer following
    finally:
        server.stop()
