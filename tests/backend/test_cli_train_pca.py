"""``visioncell train-pca``: a small real training run, source selection, skipped kinds."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from backend.cli.features import train_pca
from vision.features.pca import load_npz

pytest.importorskip("skimage")


def _invoke(*args: str):
    """Through ``backend.cli`` once the lead has registered the command, else a local app."""
    from backend.cli import app

    names = {c.name for c in app.registered_commands}
    if "train-pca" in names:
        return CliRunner().invoke(app, ["train-pca", *args])
    local = typer.Typer()
    local.command("train-pca")(train_pca)
    local.command("noop")(lambda: None)  # two commands: keep the sub-command name
    return CliRunner().invoke(local, ["train-pca", *args])


def _fake_oxford(root):
    rng = np.random.default_rng(0)
    for seq in ("graf", "wall"):
        d = root / "registration" / "oxford" / seq
        d.mkdir(parents=True)
        img = cv2.GaussianBlur(rng.integers(0, 255, (160, 200, 3), dtype=np.uint8), (0, 0), 2)
        cv2.imwrite(str(d / "img1.png"), img)


def test_small_run_writes_versioned_bases_with_provenance(tmp_path):
    _fake_oxford(tmp_path / "data")
    res = _invoke(
        "--out", str(tmp_path / "out"),
        "--kind", "gloh",
        "--kind", "color-sift",
        "--patches", "500",
        "--photo", "astronaut",
        "--photo", "coffee",
        "--sim-frames", "0",
        "--max-features", "400",
        "--data-dir", str(tmp_path / "data"),
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    for kind, dims in (("gloh", (272, 128)), ("color-sift", (256, 32))):
        b = load_npz(tmp_path / "out" / f"{kind}.npz")
        assert (b.dim_in, b.dim_out) == dims
        assert b.version in res.output
        prov = b.provenance
        assert prov["patches"] == 500 and prov["seed"] == 0 and prov["date"]
        names = [s["name"] for s in prov["sources"]]
        # The benchmark's graf sequence is excluded, the other Oxford sequence is used.
        assert names == ["skimage:astronaut", "skimage:coffee", "oxford:wall/img1.png"]
        assert sum(s["patches"] for s in prov["sources"]) == 500
        assert prov["source_sets"]["oxford"]["excluded_sequences"] == ["graf", "boat", "bikes"]
    assert not (tmp_path / "out" / "pca-sift.npz").exists()


def test_same_seed_same_basis_other_seed_other_version(tmp_path):
    args = ["--kind", "gloh", "--patches", "150", "--photo", "chelsea", "--sim-frames", "0",
            "--no-oxford", "--max-features", "300"]  # fmt: skip
    for out, seed in (("a", "0"), ("b", "0"), ("c", "1")):
        assert _invoke("--out", str(tmp_path / out), "--seed", seed, *args).exit_code == 0
    va, vb, vc = (load_npz(tmp_path / d / "gloh.npz").version for d in "abc")
    assert va == vb != vc


def test_errors_and_skipped_kinds(tmp_path, monkeypatch):
    res = _invoke("--kind", "sift", "--out", str(tmp_path))
    assert res.exit_code == 2 and "--kind 'sift'" in res.output
    res = _invoke("--photo", "lena", "--out", str(tmp_path), "--sim-frames", "0")
    assert res.exit_code == 2 and "--photo 'lena'" in res.output
    res = _invoke("--no-skimage", "--no-oxford", "--sim-frames", "0", "--out", str(tmp_path))
    assert res.exit_code == 1 and "no training images" in res.output

    import vision.features.pca_training as training

    monkeypatch.setattr(
        training, "unavailable_reason", lambda kind: "SURF missing" if kind == "gloh" else None
    )
    res = _invoke("--kind", "gloh", "--out", str(tmp_path))
    assert res.exit_code == 1
    assert "skipping gloh" in res.output and "SURF missing" in res.output


@pytest.mark.slow
def test_sim_frames_render_the_cell(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")
    from backend.cli.features import sim_frames

    frames = sim_frames(2)
    assert [n for n, _ in frames] == ["sim:top-0", "sim:inner-0"]
    for _, rgb in frames:
        assert rgb.dtype == np.uint8 and rgb.shape == (480, 640, 3)
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        assert len(cv2.SIFT_create().detect(grey)) > 100  # textured enough to train on
