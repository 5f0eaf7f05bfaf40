"""The vectorised collision check agrees with the one-configuration check."""

import numpy as np
import pytest

from robot.model import ASEA
from robot.sim.obstacles import collision_world


def test_collides_many_matches_collides():
    world = collision_world()
    rng = np.random.default_rng(5)
    qs = rng.uniform(ASEA.lower, ASEA.upper, size=(300, 5))
    many = world.collides_many(qs)
    one = np.array([world.collides(q) for q in qs])
    assert np.array_equal(many, one)
    assert 0 < many.sum() < len(qs)  # both outcomes are exercised
    assert world.collides_many(np.zeros((0, 5))).shape == (0,)
    with pytest.raises(ValueError, match="finite"):
        world.collides_many([[np.nan] * 5])
