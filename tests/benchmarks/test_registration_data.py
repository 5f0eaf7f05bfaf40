"""benchmarks.registration_data: the illumination models do what they say, the ground-truth
homographies of the synthetic and simulated pairs hold, the Oxford loader; and a smoke run of
``python -m benchmarks.registration --quick``."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from benchmarks import registration_data as rd
from vision.evaluation import apply_homography
from vision.features import extract
from vision.registration import register


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return rd.skimage_photo("astronaut")


def test_gain_multiplies_each_channel(photo):
    out = rd.apply_illumination(photo, "gain", (1.2, 1.0, 0.5))
    f = photo.astype(float)
    np.testing.assert_array_equal(out[..., 1], photo[..., 1])
    np.testing.assert_allclose(out[..., 2], np.rint(f[..., 2] * 0.5), atol=0)
    unclipped = f[..., 0] * 1.2 <= 255
    np.testing.assert_allclose(out[..., 0][unclipped], np.rint(f[..., 0][unclipped] * 1.2))
    assert out[..., 0][~unclipped].min() == 255


def test_cast_warms_red_and_cools_blue(photo):
    out = rd.apply_illumination(photo, "cast", (0.2,)).astype(float)
    f = photo.astype(float)
    np.testing.assert_array_equal(out[..., 1], f[..., 1])
    assert out[..., 0].mean() > f[..., 0].mean() and out[..., 2].mean() < f[..., 2].mean()
    np.testing.assert_allclose(out[..., 2], np.rint(f[..., 2] * 0.8))


def test_shading_is_a_horizontal_ramp_that_keeps_colour_ratios(photo):
    out = rd.apply_illumination(photo, "shading", (0.6,)).astype(float)
    f = photo.astype(float)
    left, right = out[:, :20].mean() / f[:, :20].mean(), out[:, -20:].mean() / f[:, -20:].mean()
    assert left == pytest.approx(0.7, abs=0.02) and right == pytest.approx(1.3, abs=0.03)
    # Same gain for every channel at a pixel: log(R/G) (chapter eq. 17) barely changes where
    # nothing clips.
    ok = (f[..., :2] > 40).all(-1) & (out[..., :2] < 250).all(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.log(out[..., 0] / out[..., 1]) - np.log(f[..., 0] / f[..., 1])
    assert np.abs(d[ok]).max() < 0.05


def test_gamma_follows_the_power_law(photo):
    out = rd.apply_illumination(photo, "gamma", (2.0,))
    want = np.rint(255 * (photo / 255.0) ** 2).astype(np.uint8)
    np.testing.assert_array_equal(out, want)


def test_illumination_models_refuse_bad_input(photo):
    with pytest.raises(ValueError, match="model must be one of"):
        rd.apply_illumination(photo, "fog", (1.0,))
    with pytest.raises(ValueError, match="RGB uint8"):
        rd.apply_illumination(photo[..., 0], "gain", (1, 1, 1))
    with pytest.raises(ValueError, match="3 channel gains"):
        rd.apply_illumination(photo, "gain", (1.0,))


def test_illumination_pair_homography_maps_pixels(photo):
    pair = next(p for p in rd.illumination_pairs(("astronaut",)) if p.name.endswith("/gain"))
    pts = np.array([[150.0, 200.0], [300.0, 260.0], [256.0, 100.0]])
    q = np.rint(apply_homography(pair.H, pts)).astype(int)
    gain = np.array(rd.ILLUMINATION_MODELS["gain"])
    for (x, y), (u, v) in zip(pts.astype(int), q, strict=True):
        want = np.clip(photo[y - 2 : y + 3, x - 2 : x + 3].reshape(-1, 3).mean(0) * gain, 0, 255)
        got = pair.b[v - 2 : v + 3, u - 2 : u + 3].reshape(-1, 3).mean(0)
        np.testing.assert_allclose(got, want, atol=25)


def test_scale_pairs_ground_truth_agrees_with_registration(photo):
    (pair,) = rd.scale_pairs(photo, (2.0,))
    assert pair.b.shape[:2] == (256, 256)
    r = register(pair.a, pair.b)
    g = np.array([[100.0, 100.0], [400.0, 150.0], [250.0, 400.0]])
    e = np.linalg.norm(apply_homography(r.H, g) - apply_homography(pair.H, g), axis=1)
    assert e.max() < 1.0


def test_oxford_pairs(data_dir):
    try:
        pairs = rd.oxford_pairs(data_dir, "graf", (2, 6))
    except FileNotFoundError as exc:
        pytest.skip(str(exc))
    assert [p.param for p in pairs] == [20.0, 60.0]
    assert pairs[0].a.shape == (640, 800, 3) and pairs[0].H.shape == (3, 3)
    with pytest.raises(ValueError, match="sequence"):
        rd.oxford_pairs(data_dir, "wall")


@pytest.mark.slow
def test_sim_wheel_pairs_ground_truth_holds_on_the_wheel():
    pairs = rd.sim_wheel_pairs(views=(("rotated", 30.0, 0.0, 0.42),))
    (p,) = pairs
    m = p.mask_a.astype(np.uint8)
    mb = cv2.warpPerspective(m, p.H, (p.b.shape[1], p.b.shape[0]), flags=cv2.INTER_NEAREST)
    r = register(extract(p.a, "sift", mask=m), extract(p.b, "sift", mask=mb))
    ys, xs = np.nonzero(p.mask_a)
    g = np.c_[xs, ys][:: max(1, len(xs) // 50)].astype(float)
    e = np.linalg.norm(apply_homography(r.H, g) - apply_homography(p.H, g), axis=1)
    # The top-plane homography is exact on the plane; the rim face lies a little below it.
    assert np.median(e) < 3.0


@pytest.mark.slow
def test_benchmark_quick_smoke(tmp_path, capsys):
    from benchmarks.registration import main

    code = main(
        [
            "--quick",
            "--json",
            "--methods",
            "orb",
            "--sequences",
            "illumination",
            "scale",
            "--plots",
            str(tmp_path),
            "--max-features",
            "500",
        ]
    )
    assert code == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(result) >= {"methods", "skipped", "summary", "timing_640", "targets", "plots"}
    assert result["methods"] == ["sift", "orb"]
    s = result["summary"]["orb"]["illumination"]
    assert set(s) >= {"recall_at_01", "auc", "extract_ms", "match_ms", "recall_vs_sift"}
    assert 0.0 <= s["recall_at_01"] <= 1.0
    assert {t["status"] for t in result["targets"]} <= {"PASS", "MISS", "SKIP"}
    assert any(p.endswith("fig12_scale.png") for p in result["plots"])
    assert (tmp_path / "fig12_scale.png").stat().st_size > 1000
