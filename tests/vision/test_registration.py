"""vision.registration: matching (ratio test, mutual check, exact vs FLANN), robust verification
and the registration score."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision.evaluation import apply_homography
from vision.features import Features, Keypoints, extract
from vision.registration import Matches, match, nearest_neighbours, register, verify


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    from skimage import data

    return np.ascontiguousarray(data.astronaut())


@pytest.fixture(scope="module")
def warp() -> np.ndarray:
    return np.array([[0.92, 0.12, 18.0], [-0.1, 0.95, 25.0], [1.2e-4, -6e-5, 1.0]])


def _features(desc: np.ndarray, xy: np.ndarray | None = None, method: str = "test") -> Features:
    n = len(desc)
    xy = np.c_[np.arange(n) * 10.0, np.arange(n) * 7.0] if xy is None else xy
    kp = Keypoints(xy, np.full(n, 8.0), np.zeros(n), np.ones(n), np.zeros(n, np.int32))
    binary = desc.dtype == np.uint8
    return Features(kp, desc, method, "1", binary, (480, 640))


def test_registration_recovers_known_homography(photo, warp):
    b = cv2.warpPerspective(photo, warp, (512, 512))
    r = register(photo, b, method="sift")
    assert r.H is not None
    # Error of the recovered map over the central part of the image, in pixels.
    g = np.stack(np.meshgrid(np.linspace(100, 400, 7), np.linspace(100, 400, 7)), -1)
    g = g.reshape(-1, 2)
    e = np.linalg.norm(apply_homography(r.H, g) - apply_homography(warp, g), axis=1)
    assert e.max() < 1.0
    assert r.score > 0.8
    assert r.n_inliers > 100


def test_score_is_one_for_same_image_and_near_zero_for_unrelated(photo):
    from skimage import data

    same = register(photo, photo)
    assert same.score > 0.95
    for other in (data.coffee(), data.chelsea()):
        r = register(photo, np.ascontiguousarray(other))
        assert 0.0 <= r.score < 0.1, (r.score, r.n_inliers, len(r.matches))


def test_score_terms_are_in_unit_interval(photo, warp):
    b = cv2.warpPerspective(photo, warp, (512, 512))
    r = register(photo, b, method="orb")
    for v in (r.score, r.saturation, r.inlier_ratio, r.coverage):
        assert 0.0 <= v <= 1.0
    assert r.score == pytest.approx(r.saturation * np.sqrt(r.inlier_ratio * r.coverage))


def test_ratio_test_keeps_only_distinctive_matches():
    # a0 is nearest to b0 (d=1) with b1 close behind (d=1.2): ambiguous, ratio 0.83.
    # a1 is nearest to b2 (d=1) and far from others: ratio small.
    a = np.array([[0, 0, 0, 0], [10, 10, 0, 0]], np.float32)
    b = np.array([[1, 0, 0, 0], [0, 1.2, 0, 0], [10, 11, 0, 0]], np.float32)
    fa, fb = _features(a), _features(b)
    loose = match(fa, fb, ratio=None, mutual=False)
    assert sorted(zip(loose.index_a, loose.index_b, strict=True)) == [(0, 0), (1, 2)]
    strict = match(fa, fb, ratio=0.8, mutual=False)
    assert list(zip(strict.index_a, strict.index_b, strict=True)) == [(1, 2)]
    assert strict.ratio[0] == pytest.approx(1.0 / np.hypot(10, 8.8), rel=1e-5)  # 2nd: b1
    assert match(fa, fb, ratio=0.9, mutual=False).index_a.tolist() == [0, 1]


def test_mutual_check_drops_one_sided_matches():
    # Both a0 and a1 have b0 as nearest; b0's nearest is a0 only.
    a = np.array([[0, 0], [3, 0]], np.float32)
    b = np.array([[0.5, 0], [20, 20]], np.float32)
    fa, fb = _features(a), _features(b)
    one_way = match(fa, fb, ratio=None, mutual=False)
    assert sorted(one_way.index_a.tolist()) == [0, 1]
    both = match(fa, fb, ratio=None, mutual=True)
    assert both.index_a.tolist() == [0]
    assert both.index_b.tolist() == [0]


def test_binary_descriptors_use_hamming():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (50, 32), dtype=np.uint8)
    b = a.copy()
    b[:, 0] ^= 0b1  # one bit off each
    nn = nearest_neighbours(_features(a), _features(b), method="exact")
    assert nn.index.tolist() == list(range(50))
    assert np.all(nn.distance == 1.0)


@pytest.mark.parametrize("binary", [False, True])
def test_flann_agrees_with_exact_on_large_set(binary):
    rng = np.random.default_rng(1)
    n = 3000
    if binary:
        base = rng.integers(0, 256, (n, 32), dtype=np.uint8)
        noisy = base.copy()
        flips = (
            rng.integers(0, 256, (n, 32), dtype=np.uint8)
            & rng.integers(0, 256, (n, 32), dtype=np.uint8)
            & rng.integers(0, 256, (n, 32), dtype=np.uint8)
        )
        noisy ^= flips & 0b00000001
    else:
        base = rng.normal(size=(n, 64)).astype(np.float32)
        noisy = base + rng.normal(scale=0.05, size=base.shape).astype(np.float32)
    fa, fb = _features(base), _features(noisy[rng.permutation(n)])
    exact = match(fa, fb, method="exact")
    approx = match(fa, fb, method="flann")
    assert approx.method == "flann" and exact.method == "exact"
    pe = set(zip(exact.index_a.tolist(), exact.index_b.tolist(), strict=True))
    pa = set(zip(approx.index_a.tolist(), approx.index_b.tolist(), strict=True))
    assert len(pe) > 0.9 * n
    assert len(pe & pa) >= 0.95 * len(pe)
    # "auto" switches to FLANN for sets this large.
    assert match(fa, fb, method="auto").method == "flann"


def test_verify_affine_and_ransac(photo):
    A = np.array([[0.9, -0.2, 30.0], [0.2, 0.9, -10.0], [0, 0, 1.0]])
    b = cv2.warpAffine(photo, A[:2], (512, 512))
    fa, fb = extract(photo, "sift"), extract(b, "sift")
    m = match(fa, fb)
    for method in ("usac_magsac", "ransac"):
        v = verify(m, fa, fb, model="affine", method=method)
        assert v.found and v.n_inliers > 50
        np.testing.assert_allclose(v.H, A, atol=0.05 * np.abs(A).max())
        assert v.H[2].tolist() == [0.0, 0.0, 1.0]


def test_verify_with_too_few_matches_finds_nothing():
    fa = _features(np.eye(3, 8, dtype=np.float32))
    m = Matches(np.arange(3), np.arange(3), np.zeros(3), np.zeros(3), "exact")
    v = verify(m, fa, fa)
    assert not v.found and v.H is None and v.n_inliers == 0


def test_bad_input_names_the_problem(photo):
    f = _features(np.ones((3, 8), np.float32))
    empty = Features(Keypoints.empty(), np.zeros((0, 8), np.float32), "test", "1")
    with pytest.raises(ValueError, match=r"features b .* empty"):
        match(f, empty)
    with pytest.raises(ValueError, match="methods differ: a is 'test', b is 'other'"):
        match(f, _features(np.ones((3, 8), np.float32), method="other"))
    other_version = Features(f.keypoints, f.descriptors, "test", "2")
    with pytest.raises(ValueError, match="versions of 'test' differ"):
        match(f, other_version)
    binary = Features(f.keypoints, np.ones((3, 8), np.uint8), "test", "1", binary=True)
    with pytest.raises(ValueError, match="kinds differ"):
        match(f, binary)
    with pytest.raises(ValueError, match="ratio must be in"):
        match(f, f, ratio=1.5)
    with pytest.raises(ValueError, match="method must be one of"):
        match(f, f, method="annoy")
    m = match(f, f, ratio=None)
    with pytest.raises(ValueError, match="model must be one of"):
        verify(m, f, f, model="projective")
    with pytest.raises(ValueError, match="reproj_px"):
        verify(m, f, f, reproj_px=0.0)
    with pytest.raises(ValueError, match="image array or Features"):
        register("a.png", photo)
    with pytest.raises(ValueError, match="empty"):
        register(np.zeros((64, 64, 3), np.uint8), photo)
