import math
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from robot.kinematics import T_base_ee
from robot.model import ASEA
from robot.urdf import urdf_from_model


def test_urdf_is_well_formed_with_the_model_limits():
    root = ET.fromstring(urdf_from_model())
    joints = root.findall("joint")
    assert [j.get("name") for j in joints] == [f"joint{i}" for i in range(1, 6)]
    assert all(j.get("type") == "revolute" for j in joints)
    for j, (lo, hi) in zip(joints, ASEA.joint_limits_rad, strict=True):
        lim = j.find("limit")
        assert float(lim.get("lower")) == lo and float(lim.get("upper")) == hi
    links = {link.get("name") for link in root.findall("link")}
    assert {"base_link", "flange"} <= links


def _chain(tmp_path):
    ikpy_chain = pytest.importorskip("ikpy.chain", reason="ikpy (bench extra) is not installed")
    path = tmp_path / "asea.urdf"
    path.write_text(urdf_from_model())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ikpy_chain.Chain.from_urdf_file(
            str(path), base_elements=["base_link"], active_links_mask=[False] + [True] * 5
        )


def test_ikpy_forward_kinematics_of_the_urdf_equals_ours(tmp_path):
    chain = _chain(tmp_path)
    rng = np.random.default_rng(0)
    wide = rng.uniform(-math.pi, math.pi, (200, 5))  # the geometry, not only the ranges
    inside = rng.uniform(ASEA.lower, ASEA.upper, (200, 5))
    for q in np.vstack([wide, inside, ASEA.q_home, ASEA.q_ready]):
        T = chain.forward_kinematics([0.0, *q])
        np.testing.assert_allclose(T, T_base_ee(q), atol=1e-9)
