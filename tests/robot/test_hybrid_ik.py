import numpy as np
import pytest

from robot.kinematics import fk, hybrid_ik, hybrid_ik_batch, ik_batch
from robot.kinematics.hybrid import nominal_model_estimator
from robot.model import ASEA


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(ASEA.lower, ASEA.upper, (n, 5))
    return fk(q), q


def test_the_nominal_estimate_is_wrong_and_the_loop_corrects_it():
    pose = fk(ASEA.q_ready)
    est = nominal_model_estimator()
    first = est(pose[None], np.zeros(1))[0]
    assert np.linalg.norm(fk(first)[:3] - pose[:3]) > 1e-3  # millimetres off at first
    r = hybrid_ik(pose)
    assert r.converged and r.within_limits
    assert r.iterations >= 2
    assert r.position_error_m <= 1e-10
    np.testing.assert_allclose(r.q, ASEA.q_ready, atol=1e-9)
    h = np.array(r.position_error_history_m)
    assert len(h) == r.iterations + 1
    assert np.all(np.diff(h) < 0)  # the error shrinks at every pass


def test_batch_converges_on_random_reachable_poses():
    poses, q = _poses(3000)
    r = hybrid_ik_batch(poses, q[:, 4])
    assert r.converged.all() and r.within_limits.all()
    assert r.position_error_m.max() <= 1e-10 and r.orientation_error_rad.max() <= 1e-10
    np.testing.assert_allclose(r.q, q, atol=1e-8)


def test_an_exact_estimator_needs_no_correction():
    poses, q = _poses(50, seed=1)

    def exact(p, roll):
        return ik_batch(p, roll)[0]

    r = hybrid_ik_batch(poses, q[:, 4], estimator=exact)
    assert (r.iterations == 0).all() and r.converged.all()


def test_a_useless_estimator_is_reported_as_not_converged():
    poses, q = _poses(5, seed=2)

    def constant(p, roll):
        return np.tile(ASEA.q_home, (p.shape[0], 1))

    r = hybrid_ik_batch(poses, q[:, 4], estimator=constant, max_iterations=10)
    assert not r.converged.any()
    assert (r.iterations == 10).all()


def test_estimator_giving_up_stops_the_row():
    poses, q = _poses(4, seed=3)

    def nan(p, roll):
        return np.full((p.shape[0], 5), np.nan)

    r = hybrid_ik_batch(poses, q[:, 4], estimator=nan)
    assert not r.converged.any() and (r.iterations == 0).all() and not r.within_limits.any()


@pytest.mark.parametrize("kw", [{"tol_m": 0.0}, {"gain": 0.0}, {"max_iterations": -1}])
def test_bad_parameters(kw):
    with pytest.raises(ValueError):
        hybrid_ik(fk(ASEA.q_ready), **kw)
