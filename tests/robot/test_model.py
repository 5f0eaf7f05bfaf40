import math

import numpy as np
import pytest

from robot.errors import JointLimitError
from robot.kinematics import fk
from robot.model import ASEA, check_joints


def test_table1_constants_in_si_units():
    assert ASEA.link_lengths_m == (0.730, 0.690, 0.670, 0.073, 0.020)
    spans_deg = np.degrees(ASEA.upper - ASEA.lower)
    np.testing.assert_allclose(spans_deg, [360.0, 82.5, 63.0, 208.5, 331.5], atol=1e-9)


def test_named_configurations_are_within_limits():
    assert ASEA.within_limits(ASEA.q_home)
    assert ASEA.within_limits(ASEA.q_ready)


def test_q_ready_looks_down_on_the_inspection_station():
    x, y, z, u, w = fk(ASEA.q_ready)
    assert (x, y, z) == pytest.approx((0.80, 0.0, 1.00), abs=1e-12)
    assert (u, w) == pytest.approx((0.0, -1.0), abs=1e-12)


def test_check_joints_names_joint_value_and_limit():
    q = np.array(ASEA.q_home)
    q[2] = math.radians(-50.0)
    with pytest.raises(JointLimitError) as e:
        check_joints(q)
    assert e.value.joint == 3
    assert "q3" in str(e.value) and "-50.00 deg" in str(e.value) and "-126.00" in str(e.value)


@pytest.mark.parametrize("bad", [np.zeros(4), np.zeros((2, 3)), [0, 1.5, -1.5, np.nan, 0]])
def test_check_joints_rejects_bad_shapes_and_nan(bad):
    with pytest.raises(ValueError):
        check_joints(bad)
