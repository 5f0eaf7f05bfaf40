import math

import numpy as np
import pytest

from robot.kinematics import fk
from robot.kinematics.fuzzy import SugenoIK, initial_sugeno, sse, tune_consequents
from robot.kinematics.fuzzy_ga import (
    GAConfig,
    crossover,
    decode,
    gene_ranges,
    mutate,
    roulette_wheel,
    tune_antecedents,
)
from robot.kinematics.fuzzy_protocol import (
    STATION_REGION,
    WORKSPACE_REGION,
    run_chapter_protocol,
    sample_poses,
)
from robot.model import ASEA


def test_gene_ranges_are_plus_minus_a_third_as_in_the_chapter_example():
    # The chapter: the Low mean of x varied between -1.7373 and -0.8686 m, sigma 0.66..1.33.
    mean = np.tile([-1.30295, 1.30295], (5, 1))
    fis0 = SugenoIK(mean, np.ones((5, 2)), np.zeros((32, 5)))
    lo, hi = gene_ranges(fis0)
    assert (lo[0], hi[0]) == pytest.approx((-1.7373, -0.8686), abs=1e-4)  # x Low mean
    assert (lo[1], hi[1]) == pytest.approx((2 / 3, 4 / 3), abs=1e-12)  # x Low sigma
    assert (lo[2], hi[2]) == pytest.approx((0.8686, 1.7373), abs=1e-4)  # x High mean
    assert lo.shape == hi.shape == (20,)


def test_a_zero_initial_mean_is_varied_by_a_third_of_its_sigma():
    mean = np.tile([0.0, 1.0], (5, 1))
    fis0 = SugenoIK(mean, np.full((5, 2), 0.6), np.zeros((32, 5)))
    lo, hi = gene_ranges(fis0)
    assert (lo[0], hi[0]) == pytest.approx((-0.2, 0.2))


def test_decoding_10_bit_genes_into_their_ranges():
    lo, hi = np.arange(20.0), np.arange(20.0) + 3.0
    zeros = np.zeros(200, dtype=np.int8)
    np.testing.assert_allclose(decode(zeros, lo, hi), lo)
    np.testing.assert_allclose(decode(np.ones(200, dtype=np.int8), lo, hi), hi)
    bits = zeros.copy()
    bits[10] = 1  # gene 1, most significant bit: 512 / 1023 of the range
    bits[29] = 1  # gene 2, least significant bit: 1 / 1023
    v = decode(bits[None], lo, hi)[0]
    assert v[1] == pytest.approx(1.0 + 3.0 * 512 / 1023)
    assert v[2] == pytest.approx(2.0 + 3.0 / 1023)
    assert v[0] == lo[0] and v[3] == lo[3]
    with pytest.raises(ValueError, match="200 columns"):
        decode(np.zeros(199), lo, hi)


def test_roulette_wheel_selects_in_proportion_to_fitness():
    rng = np.random.default_rng(0)
    f = np.array([1.0, 2.0, 3.0, 4.0, 0.0])
    idx = roulette_wheel(f, 200_000, rng)
    freq = np.bincount(idx, minlength=5) / idx.size
    np.testing.assert_allclose(freq, f / f.sum(), atol=0.005)
    assert freq[4] == 0.0
    with pytest.raises(ValueError):
        roulette_wheel([-1.0, 2.0], 3, rng)


def test_single_point_crossover_swaps_tails():
    rng = np.random.default_rng(1)
    parents = np.vstack([np.zeros(200), np.ones(200)]).astype(np.int8)
    kids = crossover(parents, 1.0, rng)
    cut = int(np.argmax(kids[0] != 0))
    assert 1 <= cut <= 199
    assert (kids[0, :cut] == 0).all() and (kids[0, cut:] == 1).all()
    np.testing.assert_array_equal(kids[1], 1 - kids[0])
    np.testing.assert_array_equal(crossover(parents, 0.0, rng), parents)


def test_crossover_happens_with_its_probability():
    rng = np.random.default_rng(2)
    parents = np.tile(np.vstack([np.zeros(200), np.ones(200)]).astype(np.int8), (2000, 1))
    kids = crossover(parents, 0.95, rng)
    crossed = (kids[0::2] != parents[0::2]).any(axis=1)
    assert crossed.mean() == pytest.approx(0.95, abs=0.015)


def test_mutation_flips_bits_at_its_rate():
    rng = np.random.default_rng(3)
    bits = np.zeros((20, 200 * 50), dtype=np.int8)
    m = mutate(bits, 0.01, rng)
    assert m.mean() == pytest.approx(0.01, abs=0.001)
    np.testing.assert_array_equal(mutate(bits, 0.0, rng), bits)
    assert bits.sum() == 0  # the input is not modified


def _training_set(n=60):
    X, Q = sample_poses(STATION_REGION, n, np.random.default_rng(0))
    U = np.column_stack([X.min(axis=0), X.max(axis=0)])
    fis0 = initial_sugeno(U, 0.5 * (ASEA.lower + ASEA.upper))
    return fis0, X, Q


def test_ga_tuning_reduces_the_error_and_is_seeded():
    fis0, X, Q = _training_set()
    cfg = GAConfig(generations=4, consequent_epochs=400, seed=11)
    res = tune_antecedents(fis0, X, Q, config=cfg)
    assert res.evaluations == 20 * 5
    h = res.best_sse_history
    assert h.shape == (5,) and np.all(np.diff(h) <= 0)
    assert sse(res.fis, X, Q) == pytest.approx(h[-1])
    assert sse(res.fis, X, Q) < sse(fis0, X, Q) / 10
    # MFs stay within +-1/3 of their initial values.
    lo, hi = gene_ranges(fis0)
    g = np.column_stack(
        [res.fis.mean[:, 0], res.fis.sigma[:, 0], res.fis.mean[:, 1], res.fis.sigma[:, 1]]
    ).ravel()
    assert np.all(g >= np.minimum(lo, hi) - 1e-12) and np.all(g <= np.maximum(lo, hi) + 1e-12)
    again = tune_antecedents(fis0, X, Q, config=cfg)
    np.testing.assert_array_equal(again.fis.mean, res.fis.mean)


def test_consequent_tuning_alone_reduces_the_error():
    fis0, X, Q = _training_set()
    fit = tune_consequents(fis0, X, Q, epochs=2000)
    assert sse(fit.fis, X, Q) < 0.05 * sse(fis0, X, Q)


def test_sampled_regions_are_reachable_and_inside_their_box():
    rng = np.random.default_rng(4)
    X, Q = sample_poses(STATION_REGION, 200, rng)
    (x0, x1), (y0, y1), (z0, z1), (p0, p1) = STATION_REGION.box
    phi = np.arctan2(X[:, 4], X[:, 3])
    assert np.all((X[:, 0] >= x0) & (X[:, 0] <= x1) & (X[:, 2] >= z0) & (X[:, 2] <= z1))
    assert np.all((X[:, 1] >= y0) & (X[:, 1] <= y1) & (phi >= p0) & (phi <= p1))
    assert ASEA.within_limits(Q).all() and np.all(Q[:, 4] == 0)
    Xw, Qw = sample_poses(WORKSPACE_REGION, 50, rng)
    assert ASEA.within_limits(Qw).all()
    np.testing.assert_allclose(Xw, fk(Qw), atol=1e-15)
    assert "phi in [-120, -60] deg" in STATION_REGION.describe()


def test_protocol_runs_end_to_end_on_a_small_budget():
    steps = []
    rep = run_chapter_protocol(
        n_train=40,
        n_test=10,
        config=GAConfig(generations=2, consequent_epochs=300),
        timing_calls=20,
        progress=lambda f, m: steps.append((f, m)),
    )
    assert steps[-1][0] == pytest.approx(1.0) and "GA cycle 2/2" in steps[-1][1]
    assert rep.sse_consequents_only < rep.sse_untuned
    assert rep.sse_tuned_least_squares <= rep.sse_tuned * (1 + 1e-9)
    assert rep.test_sse_per_pose.shape == (10,) and rep.test_position_error_m.shape == (10,)
    assert 0 < rep.inference_s < 1.0 and math.isfinite(rep.gd_learning_rate)
    assert rep.fis is rep.ga.fis
