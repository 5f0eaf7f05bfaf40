"""benchmarks.features_crop, short: on a few masked views uploaded through the API, the
crop round the mask finds the whole image's keypoints again, and the figures are there."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

from backend.app import create_app
from benchmarks.features_crop import measure
from tests.utils.factories import make_settings, make_tokens, migrate
from tests.utils.models import png_bytes, textured_rgb


def test_crop_keeps_the_keypoints_of_the_whole_image(tmp_path):
    settings = make_settings(tmp_path)
    migrate(settings)
    hdr = {"Authorization": f"Bearer {make_tokens(settings)['engineer']}"}
    with TestClient(create_app(settings)) as client:
        mid = client.post("/api/models", json={"name": "part", "kind": "3d"}, headers=hdr).json()[
            "id"
        ]
        for seed in range(3):
            img = textured_rgb(seed, size=(480, 640))
            mask = np.zeros(img.shape[:2], np.uint8)
            mask[150 + 20 * seed : 330, 200 : 420 + 30 * seed] = 255
            files = [("images", ("v.png", png_bytes(img), "image/png")),
                     ("masks", ("m.png", png_bytes(mask), "image/png"))]  # fmt: skip
            r = client.post(f"/api/models/{mid}/views", files=files, data={"viewpoints": "1"},
                            headers=hdr)  # fmt: skip
            assert r.status_code == 201, r.text
    r = measure(tmp_path / "test.db", 3)
    assert r["views"] == 3
    # Texture runs up to the mask's edge here (0.74 of the kept keypoints had the same
    # descriptor in this scene: large keypoints' windows meet the crop's edge).
    assert r["same_keypoints_p50"] >= 0.85 and r["same_descriptors_p50"] >= 0.5, r
    assert r["whole_ms_p50"] > 0 and r["crop_ms_p50"] > 0
