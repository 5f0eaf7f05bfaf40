"""PinholeCamera: bad input is refused with messages that name the value; FOV helpers."""

import math

import numpy as np
import pytest

from vision.camera import (
    PinholeCamera,
    T_from_rvec_tvec,
    check_dist,
    focal_from_fov,
    fov_from_focal,
    rotation_from_rvec,
)

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize(
    ("bad_K", "match"),
    [
        (np.eye(2), r"K must have shape \(3, 3\)"),
        (np.array([[np.nan, 0, 1], [0, 1, 1], [0, 0, 1]]), "NaN"),
        (np.array([[-5.0, 0, 1], [0, 1, 1], [0, 0, 1]]), "fx=-5.0"),
        (np.array([[5.0, 0, 1], [0, 0.0, 1], [0, 0, 1]]), "fy=0.0"),
        (np.array([[5.0, 0, 1], [0, 5.0, 1], [0, 0, 2]]), "last row"),
        (np.array([[5.0, 0, 1], [0.3, 5.0, 1], [0, 0, 1]]), "upper triangular"),
    ],
)
def test_bad_K_is_refused(bad_K, match):
    with pytest.raises(ValueError, match=match):
        PinholeCamera(bad_K)


@pytest.mark.parametrize("dist", [[0.1], [0.1, 0.2, 0.3], [0.0] * 6, [0.0] * 8])
def test_dist_of_wrong_length_is_refused(dist):
    with pytest.raises(ValueError, match=f"got {len(dist)}"):
        PinholeCamera(K, dist)


def test_dist_with_nan_is_refused():
    with pytest.raises(ValueError, match="dist contains NaN"):
        PinholeCamera(K, [0.1, np.nan, 0, 0])


def test_dist_lengths_pad_to_five_and_radial_only_flag():
    assert check_dist(None).tolist() == [0.0] * 5
    assert check_dist([0.1, 0.2]).tolist() == [0.1, 0.2, 0.0, 0.0, 0.0]
    assert check_dist([0.1, 0.2, 0.01, 0.02]).tolist() == [0.1, 0.2, 0.01, 0.02, 0.0]
    assert PinholeCamera(K, [-0.2, 0.05]).is_radial_only
    assert not PinholeCamera(K, [-0.2, 0.05, 0.001, 0.0]).is_radial_only


def test_bad_image_size_is_refused():
    with pytest.raises(ValueError, match="width=0"):
        PinholeCamera(K, width=0)


def test_points_with_nan_are_refused_with_their_row():
    cam = PinholeCamera(K, [-0.2, 0.05])
    P = np.array([[0.0, 0.0, 1.0], [0.1, np.nan, 2.0]])
    with pytest.raises(ValueError, match=r"points_cam contains NaN or infinity at rows \[1\]"):
        cam.project(P)
    with pytest.raises(ValueError, match="uv contains NaN"):
        cam.undistort_pixels([[np.inf, 3.0]])


def test_points_of_wrong_shape_are_refused():
    cam = PinholeCamera(K)
    with pytest.raises(ValueError, match=r"points_cam must have shape \(N, 3\), got \(4,\)"):
        cam.project(np.zeros(4))
    with pytest.raises(ValueError, match=r"T_cam_world must have shape \(4, 4\)"):
        cam.project_world(np.zeros((1, 3)), np.eye(3))


def test_points_behind_the_camera_nan_or_raise():
    cam = PinholeCamera(K, [-0.2, 0.05, 0.001, 0.001, 0.01])
    P = np.array([[0.0, 0.0, 1.0], [0.1, 0.1, -1.0], [0.2, 0.0, 0.0]])
    uv = cam.project(P)
    assert np.all(np.isfinite(uv[0])) and np.all(np.isnan(uv[1:]))
    with pytest.raises(ValueError, match=r"2 point\(s\) at or behind the camera .* rows \[1, 2\]"):
        cam.project(P, behind="raise")
    with pytest.raises(ValueError, match="behind must be"):
        cam.project(P, behind="clip")


def test_bad_rvec_tvec_are_refused():
    with pytest.raises(ValueError, match="rvec must be 3 finite numbers"):
        rotation_from_rvec([1.0, 2.0])
    with pytest.raises(ValueError, match="tvec must be 3 finite numbers"):
        T_from_rvec_tvec([0.0, 0.0, 0.0], [np.nan, 0.0, 0.0])


def test_fov_helpers_are_consistent():
    f = focal_from_fov(60.0, 480)
    assert math.isclose(fov_from_focal(f, 480), 60.0)
    cam = PinholeCamera.from_fov(60.0, width=640, height=480)
    fovx, fovy = cam.fov_deg()
    assert math.isclose(fovy, 60.0, rel_tol=1e-12)
    assert math.isclose(fovx, fov_from_focal(f, 640), rel_tol=1e-12)
    assert fovx < cam.fov_diagonal_deg() < 180.0
    # Without distortion, the distorted field of view is the pinhole's.
    assert np.allclose(cam.fov_deg(distorted=True), (fovx, fovy))


def test_barrel_distortion_widens_the_field_of_view():
    barrel = PinholeCamera.from_fov(60.0, dist=[-0.25, 0.05])
    pincushion = PinholeCamera.from_fov(60.0, dist=[0.2, 0.0])
    base = PinholeCamera.from_fov(60.0).fov_deg()
    assert barrel.fov_deg(distorted=True)[0] > base[0]
    assert pincushion.fov_deg(distorted=True)[0] < base[0]


@pytest.mark.parametrize(("fov", "size"), [(0.0, 480), (180.0, 480), (60.0, 0)])
def test_fov_helper_bad_values(fov, size):
    with pytest.raises(ValueError):
        focal_from_fov(fov, size)


def test_undistort_beyond_the_fold_is_nan_not_garbage():
    # k1 = -0.6 folds back at r^2 = 1/(3*0.6): distorted radii beyond the maximum have no
    # preimage; they must not come back as a wrong finite number.
    cam = PinholeCamera(K, [-0.6, 0.0])
    xy = cam.undistort_normalized([[0.1, 0.0], [2.0, 0.0]])
    assert np.isfinite(xy[0]).all() and np.isnan(xy[1]).all()
    with pytest.raises(ValueError, match="max_iter"):
        cam.undistort_normalized([[0.1, 0.0]], max_iter=0)
