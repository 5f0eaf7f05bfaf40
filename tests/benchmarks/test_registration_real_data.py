"""The real illumination sets of the registration benchmark (issue 17): MIMO (8-bit sRGB and
16-bit linear) and SFU (8-bit linear) scenes under several lamps, a fixed camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks import registration_data as rd
from benchmarks.registration import real_comparison

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
MIMO = DATA / "illumination" / "mimo"
SFU = DATA / "illumination" / "sfu"
needs_mimo = pytest.mark.skipif(
    not (MIMO / "linear16").is_dir(), reason=f"MIMO illumination data absent at {MIMO}"
)
needs_sfu = pytest.mark.skipif(not SFU.is_dir(), reason=f"SFU illumination data absent at {SFU}")


@needs_mimo
@pytest.mark.parametrize(("variant", "dtype"), [("srgb8", np.uint8), ("linear16", np.uint16)])
def test_mimo_pairs_every_combination_against_the_reference(variant, dtype):
    pairs = rd.mimo_pairs(DATA, variant)
    assert len(pairs) == 46  # 9 scenes x 5 + pmug: 1 (two shifted images left out)
    names = {p.name for p in pairs}
    assert "pmug/w_b" not in names and "pmug/w_r" not in names and "pmug/r_b" in names
    assert not any(p.name.endswith("/" + rd.MIMO_REFERENCE) for p in pairs)
    for p in pairs[:6]:
        assert p.sequence == f"mimo-{variant}" and p.a.dtype == dtype == p.b.dtype
        assert p.a.shape == p.b.shape == (260, 452, 3)
        np.testing.assert_array_equal(p.H, np.eye(3))
        assert p.param > 0 and not p.a.flags.writeable
    # The same reference array is shared by the pairs of a scene (features extracted once).
    lion = [p for p in pairs if p.name.startswith("lion/")]
    assert len(lion) == 5 and all(p.a is lion[0].a for p in lion)


@needs_mimo
def test_srgb8_is_the_per_image_scaled_encoding_of_linear16():
    """The README's relation, checked: the 8-bit files are sRGB of the linear values scaled
    to the image's brightest pixel (so exposure differences are only in the 16-bit set)."""
    s = rd.mimo_pairs(DATA, "srgb8")[0]
    lin = rd.mimo_pairs(DATA, "linear16")[0]
    x = lin.b.astype(np.float64) / lin.b.max()
    enc = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055) * 255
    assert np.median(np.abs(enc - s.b.astype(np.float64))) < 4


@needs_sfu
def test_sfu_pairs_leave_out_the_shifted_scene():
    pairs = rd.sfu_pairs(DATA)
    assert len(pairs) == 6 and not any(p.name.startswith("ball/") for p in pairs)
    assert {p.name.split("/")[1] for p in pairs} == set(rd.SFU_LAMPS)
    assert all(p.a.dtype == np.uint8 and p.a.mean() < 60 for p in pairs)  # dark linear


def test_absent_data_gives_reasons_not_errors(tmp_path):
    pairs, skipped = rd.real_illumination_pairs(tmp_path)
    assert pairs == [] and set(skipped) == set(rd.REAL_ILLUMINATION_SETS)
    assert all("is absent" in why for why in skipped.values())
    with pytest.raises(FileNotFoundError, match="is absent"):
        rd.mimo_pairs(tmp_path, "srgb8")
    with pytest.raises(FileNotFoundError, match="is absent"):
        rd.sfu_pairs(tmp_path)


def test_bad_arguments_raise_value_error(tmp_path):
    with pytest.raises(ValueError, match="variant must be 'srgb8' or 'linear16', got 'raw'"):
        rd.mimo_pairs(tmp_path, "raw")
    with pytest.raises(ValueError, match="sets must be among"):
        rd.real_illumination_pairs(tmp_path, ("mimo",))


def test_real_comparison_counts_ties_and_wins_per_pair():
    rows = [
        {"method": m, "sequence": "sfu-linear8", "pair": p, "recall_at_01": r}
        for m, p, r in [
            ("sift", "a", 0.5),
            ("sift", "b", 0.4),
            ("color-sift", "a", 0.6),
            ("color-sift", "b", 0.3),
        ]
    ]
    c = real_comparison(rows, "color-sift", "sift")
    assert c["sfu-linear8"]["pairs"] == 2 and c["all"]["share_ge"] == 0.5
    assert c["all"]["colour"] == pytest.approx(0.45) and c["all"]["grey"] == pytest.approx(0.45)


@needs_sfu
@pytest.mark.slow
def test_benchmark_runs_the_real_sets_with_the_grey_base(tmp_path, capsys):
    import json

    from benchmarks.registration import main

    code = main(
        [
            "--quick",
            "--json",
            "--no-variants",
            "--methods",
            "color-sift",
            "--sequences",
            "sfu-linear8",
            "--plots",
            str(tmp_path),
            "--max-features",
            "300",
        ]
    )
    assert code == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["methods"] == ["sift", "color-sift", "color-sift:full"]
    real = result["real_illumination"]["color-sift"]
    assert real["sfu-linear8"]["pairs"] == 4 and 0 <= real["all"]["share_ge"] <= 1
    names = [t["target"] for t in result["targets"]]
    assert "color-sift >= sift on >= 80 % of all real pairs" in names
    assert "color-sift extraction <= 2x sift (640x480)" in names
    assert (tmp_path / "real_illumination.png").stat().st_size > 1000
