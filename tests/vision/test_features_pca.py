"""PCA bases (chapter equations 18-19): the maths on hand-checkable data, storage, versions,
the shipped bases."""

import numpy as np
import pytest

from vision.features.pca import (
    BASIS_KINDS,
    DATA_DIR,
    PcaBasis,
    default_basis,
    fit_pca,
    load_npz,
    save_npz,
)
from vision.features.pca_training import JOINT_GREY_DIMS


def _cross(angle: float = 0.0) -> np.ndarray:
    """(+-3, 0) and (0, +-1), rotated: mean 0, covariance R diag(6, 2/3) R^T (n - 1 = 3)."""
    pts = np.array([[3.0, 0], [-3, 0], [0, 1], [0, -1]])
    c, s = np.cos(angle), np.sin(angle)
    return pts @ np.array([[c, s], [-s, c]])  # rows rotated by +angle


def test_fit_pca_on_a_known_covariance():
    b = fit_pca(_cross(), 2)
    np.testing.assert_allclose(b.mean, 0, atol=1e-7)
    np.testing.assert_allclose(b.eigenvalues, [6.0, 2.0 / 3.0], rtol=1e-12)
    np.testing.assert_allclose(np.abs(b.components), np.eye(2), atol=1e-7)
    assert b.total_variance == pytest.approx(6 + 2 / 3)
    assert b.explained_variance == pytest.approx(1.0)


def test_fit_pca_rotated_data_gives_rotated_components_and_projection():
    a = np.deg2rad(30)
    x = _cross(a) + np.array([5.0, -2.0])
    b = fit_pca(x, 1)
    np.testing.assert_allclose(b.mean, [5, -2], atol=1e-12)
    u = b.components[:, 0]
    np.testing.assert_allclose(abs(u @ [np.cos(a), np.sin(a)]), 1.0, atol=1e-6)
    assert b.explained_variance == pytest.approx(6 / (6 + 2 / 3))
    # Y = U (X - mean) (equation 18): the +-3 points project to +-3, the others to 0.
    np.testing.assert_allclose(np.abs(b.project(x)[:, 0]), [3, 3, 0, 0], atol=1e-5)


def test_fit_pca_matches_sample_covariance_of_random_data():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(500, 6)) @ rng.normal(size=(6, 6))
    b = fit_pca(x, 6)
    cov = np.cov(x, rowvar=False)  # equation 19 with 1/(n-1)
    u = b.components.astype(np.float64)
    np.testing.assert_allclose(u.T @ cov @ u, np.diag(b.eigenvalues), atol=1e-3 * b.eigenvalues[0])
    assert np.all(np.diff(b.eigenvalues) <= 0)
    # Full basis: projection then back-projection is the identity.
    y = b.project(x)
    np.testing.assert_allclose(y @ u.T + b.mean, x, atol=1e-3)


def test_fit_pca_is_deterministic_and_signs_are_fixed():
    x = np.random.default_rng(0).normal(size=(50, 5))
    a, b = fit_pca(x, 3), fit_pca(x.copy(), 3)
    assert a.version == b.version
    assert np.all(a.components[np.argmax(np.abs(a.components), axis=0), range(3)] > 0)


@pytest.mark.parametrize(
    ("samples", "k", "word"),
    [
        (np.zeros((1, 3)), 1, "samples"),
        (np.zeros(5), 1, "samples"),
        (np.zeros((4, 3)), 0, "k must"),
        (np.zeros((4, 3)), 4, "k must"),
        (np.full((4, 3), np.nan), 1, "NaN"),
    ],
)
def test_fit_pca_rejects_bad_input(samples, k, word):
    with pytest.raises(ValueError, match=word):
        fit_pca(samples, k)


def test_project_rejects_wrong_dimension():
    b = fit_pca(_cross(), 1)
    with pytest.raises(ValueError, match="dimension 3"):
        b.project(np.zeros((2, 3)))


def test_save_load_round_trip_and_versions(tmp_path):
    x = np.random.default_rng(1).normal(size=(200, 8))
    b = fit_pca(x, 4, kind="test", provenance={"sources": ["a", "b"], "seed": 1})
    p32 = save_npz(b, tmp_path / "b32.npz", float16=False)
    r = load_npz(p32)
    assert r.version == b.version and r.kind == "test"
    assert r.provenance == {"sources": ["a", "b"], "seed": 1}
    np.testing.assert_array_equal(r.components, b.components)
    np.testing.assert_array_equal(r.eigenvalues, b.eigenvalues)
    # float16 storage: a different (stable) version, projections equal to ~1e-3.
    r16 = load_npz(save_npz(b, tmp_path / "b16.npz"))
    assert r16.version != b.version
    assert load_npz(tmp_path / "b16.npz").version == r16.version
    np.testing.assert_allclose(r16.project(x), b.project(x), atol=5e-3 * np.abs(b.project(x)).max())
    # Another basis (other data) has another version.
    assert fit_pca(x[:100], 4, kind="test").version != b.version


def test_load_rejects_missing_and_tampered_files(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        load_npz(tmp_path / "nope.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a PCA basis"):
        load_npz(tmp_path / "junk.npz")
    b = fit_pca(_cross(), 2, kind="t")
    p = save_npz(b, tmp_path / "b.npz", float16=False)
    with np.load(p) as z:
        d = dict(z)
    d["components"] = d["components"] * 2
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(ValueError, match="corrupt"):
        load_npz(tmp_path / "bad.npz")


def test_basis_validates_shapes():
    with pytest.raises(ValueError, match="components"):
        PcaBasis(np.zeros(3), np.zeros((4, 2)), np.zeros(2), "x")
    with pytest.raises(ValueError, match="eigenvalues"):
        PcaBasis(np.zeros(3), np.zeros((3, 2)), np.zeros(3), "x")
    with pytest.raises(ValueError, match="kind"):
        default_basis("sift")


def test_shipped_bases_are_small_trained_and_documented():
    files = sorted(DATA_DIR.glob("*.npz"))
    assert {f.stem for f in files} >= {"pca-sift", "gloh", "color-sift"}
    assert sum(f.stat().st_size for f in files) < 600 * 1024
    for f in files:
        b = default_basis(f.stem)
        assert (b.dim_in, b.dim_out) == BASIS_KINDS[f.stem]
        prov = b.provenance
        # The joint colour bases sample only keypoints whose colour blocks carry signal
        # (the others are 0 and need no basis), so fewer than the chapter's 20,000.
        least = 8000 if f.stem in JOINT_GREY_DIMS else 15000
        assert prov["patches"] >= least and prov["seed"] == 0 and prov["date"]
        assert sum(s["patches"] for s in prov["sources"]) == prov["patches"]
        # The benchmark's Oxford sequences are not in the training set.
        assert not any(s["name"].startswith("oxford:graf") for s in prov["sources"])
        assert 0.5 < b.explained_variance <= 1.0
        assert b.version.startswith(f"{f.stem}-k{b.dim_out}-")
