import itertools
import math

import numpy as np
import pytest

from robot.kinematics.fuzzy import (
    N_RULES,
    SugenoIK,
    consequents_least_squares,
    initial_sugeno,
    rule_labels,
    sse,
    tune_consequents,
)


def _small_system(seed=0):
    rng = np.random.default_rng(seed)
    mean = np.column_stack([rng.uniform(-1, 0, 5), rng.uniform(0.5, 1.5, 5)])
    sigma = rng.uniform(0.3, 1.2, (5, 2))
    return SugenoIK(mean, sigma, rng.normal(size=(N_RULES, 5)))


def test_eq21_gives_32_rules_in_binary_label_order():
    assert N_RULES == 32
    labels = rule_labels()
    assert labels.shape == (32, 5)
    assert labels[0].tolist() == [0, 0, 0, 0, 0] and labels[31].tolist() == [1, 1, 1, 1, 1]
    assert labels[16].tolist() == [1, 0, 0, 0, 0]  # x is the most significant input
    assert len({tuple(r) for r in labels.tolist()}) == 32


def test_inference_equals_a_hand_computed_case():
    # Every input: Low at 0, High at 1, sigma 1.  q1's rule outputs are 1 where x is High and
    # 0 elsewhere, so the other inputs cancel: q1 = muH(x) / (muL(x) + muH(x)).
    mean = np.tile([0.0, 1.0], (5, 1))
    sigma = np.ones((5, 2))
    r = np.zeros((32, 5))
    r[:, 0] = rule_labels()[:, 0]
    r[:, 1] = 2.5  # a constant output stays constant
    fis = SugenoIK(mean, sigma, r)
    out = fis.infer([0.0, 0.3, -2.0, 7.0, 0.5])
    assert out[0] == pytest.approx(1.0 / (1.0 + math.exp(0.5)), abs=1e-15)  # 0.37754...
    assert out[1] == pytest.approx(2.5, abs=1e-15)
    assert out[2] == pytest.approx(0.0, abs=1e-15)


def test_inference_equals_the_rule_by_rule_weighted_average():
    fis = _small_system()
    v = np.array([0.1, -0.4, 0.9, 0.2, 1.3])
    num, den = np.zeros(5), 0.0
    for k, labels in enumerate(itertools.product((0, 1), repeat=5)):
        f = 1.0
        for i, lab in enumerate(labels):
            m, s = fis.mean[i, lab], fis.sigma[i, lab]
            f *= math.exp(-((v[i] - m) ** 2) / (2 * s * s))
        num += f * fis.consequents[k]
        den += f
    np.testing.assert_allclose(fis.infer(v), num / den, atol=1e-14)
    np.testing.assert_allclose(fis.infer(v[None])[0], num / den, atol=1e-14)
    np.testing.assert_allclose(fis.firing_strengths(v).sum(), 1.0, atol=1e-15)


def test_far_inputs_still_give_finite_outputs():
    fis = _small_system()
    out = fis.infer([1e3, -1e3, 50.0, 0.0, 0.0])
    assert np.all(np.isfinite(out))


def test_gradient_descent_step_is_eq23_with_the_analytic_gradient():
    fis = _small_system(1)
    rng = np.random.default_rng(2)
    X, Q = rng.normal(size=(40, 5)), rng.normal(size=(40, 5))
    alpha = 1e-3
    fit = tune_consequents(fis, X, Q, epochs=1, learning_rate=alpha)
    # Numerical dE/dr by central differences.
    grad = np.zeros_like(fis.consequents)
    h = 1e-6
    for k in range(N_RULES):
        for j in range(5):
            r = np.array(fis.consequents)
            r[k, j] += h
            e_plus = sse(fis.with_consequents(r), X, Q)
            r[k, j] -= 2 * h
            e_minus = sse(fis.with_consequents(r), X, Q)
            grad[k, j] = (e_plus - e_minus) / (2 * h)
    np.testing.assert_allclose(fit.fis.consequents, fis.consequents - alpha * grad, atol=1e-7)
    assert fit.sse_history[0] == pytest.approx(sse(fis, X, Q), rel=1e-10)
    assert fit.sse_history[1] == pytest.approx(sse(fit.fis, X, Q), rel=1e-10)


def test_gradient_descent_decreases_sse_towards_the_least_squares_optimum():
    fis = _small_system(3)
    rng = np.random.default_rng(4)
    X = rng.uniform(-1, 1.5, (100, 5))
    Q = np.column_stack([np.sin(X[:, 0]), X[:, 1] * X[:, 2], X[:, 3], X[:, 4] ** 2, 0 * X[:, 0]])
    fit = tune_consequents(fis, X, Q, epochs=20000)
    assert np.all(np.diff(fit.sse_history) <= 1e-12)
    e_ls = sse(consequents_least_squares(fis, X, Q), X, Q)
    assert e_ls <= sse(fit.fis, X, Q) <= e_ls * 1.05 + 1e-9
    assert sse(fit.fis, X, Q) < 0.1 * sse(fis, X, Q)


def test_initial_system_divides_each_universe_equally():
    U = np.array([[0.0, 1.0], [-0.2, 0.2], [0.5, 1.5], [-1.0, 1.0], [-1.0, 0.0]])
    fis = initial_sugeno(U, np.arange(5.0))
    np.testing.assert_allclose(fis.mean, U)
    mid = U.mean(axis=1)
    mu = fis.memberships(mid)[0]
    np.testing.assert_allclose(mu, 0.5, atol=1e-12)  # Low and High cross at 1/2 mid-way
    np.testing.assert_allclose(fis.infer(mid), np.arange(5.0), atol=1e-12)


def test_save_and_load_round_trip(tmp_path):
    fis = _small_system(5)
    path = fis.save(tmp_path / "sfis")
    assert path.suffix == ".npz"
    back = SugenoIK.load(path)
    for name in ("mean", "sigma", "consequents"):
        np.testing.assert_array_equal(getattr(back, name), getattr(fis, name))
    np.savez(tmp_path / "other.npz", mean=fis.mean)
    with pytest.raises(ValueError, match="not a VisionCell Sugeno"):
        SugenoIK.load(tmp_path / "other.npz")


def test_bad_parameters_and_inputs():
    with pytest.raises(ValueError, match="sigma"):
        SugenoIK(np.zeros((5, 2)), np.zeros((5, 2)), np.zeros((32, 5)))
    with pytest.raises(ValueError, match="shape"):
        SugenoIK(np.zeros((4, 2)), np.ones((5, 2)), np.zeros((32, 5)))
    with pytest.raises(ValueError, match="poses"):
        _small_system().infer(np.zeros(4))
