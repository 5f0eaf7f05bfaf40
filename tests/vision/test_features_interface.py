"""The feature interface: OpenCV methods, value types, serialisation, bad input."""

import cv2
import numpy as np
import pytest

from vision.features import METHODS, Features, Keypoints, extract


def _textured(seed: int = 0, shape=(240, 320)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.integers(0, 255, shape, dtype=np.uint8), (0, 0), 2.0)
    return cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)


@pytest.mark.parametrize("method", ["sift", "orb", "akaze"])
def test_opencv_methods_give_consistent_features(method):
    img = _textured()
    f = extract(img, method)
    assert len(f) > 50
    assert f.descriptors.shape[0] == len(f.keypoints)
    assert f.binary == (method != "sift")
    assert f.image_shape == img.shape
    assert f.method == method and f.version.startswith("opencv-")
    assert np.all((f.keypoints.xy >= 0) & (f.keypoints.xy < [img.shape[1], img.shape[0]]))
    assert not f.descriptors.flags.writeable


def test_sift_angle_matches_rotation_of_image():
    """A 90 deg counter-clockwise image rotation adds about +pi/2 to the matched angles."""
    img = _textured(1, (256, 256))
    rot = cv2.rotate(img, cv2.ROTATE_90_COUNTERCLOCKWISE)
    a, b = extract(img, "sift"), extract(rot, "sift")
    # (x, y) -> (y, W - 1 - x) for a CCW rotation of a square image
    mapped = np.c_[a.keypoints.xy[:, 1], 255 - a.keypoints.xy[:, 0]]
    d = np.linalg.norm(mapped[:, None] - b.keypoints.xy[None], axis=2)
    i, j = np.nonzero(d < 0.5)
    assert len(i) > 20
    diff = np.angle(np.exp(1j * (b.keypoints.angle_rad[j] - a.keypoints.angle_rad[i])))
    assert np.median(np.abs(diff - np.pi / 2)) < np.deg2rad(3)


def test_to_bytes_round_trip():
    f = extract(_textured(), "sift", max_features=100)
    g = Features.from_bytes(f.to_bytes())
    assert len(g) == len(f) <= 100
    np.testing.assert_array_equal(g.descriptors, f.descriptors)
    np.testing.assert_array_equal(g.keypoints.xy, f.keypoints.xy)
    assert (g.method, g.version, g.binary, g.image_shape) == (
        f.method,
        f.version,
        f.binary,
        f.image_shape,
    )


def test_from_bytes_rejects_garbage():
    with pytest.raises(ValueError, match="not a serialised Features"):
        Features.from_bytes(b"garbage")


def test_blank_image_gives_empty_features():
    f = extract(np.full((100, 100), 128, np.uint8), "sift")
    assert len(f) == 0 and f.descriptors.shape == (0, 128)


def test_rgb_input_is_converted_to_grey():
    img = _textured()
    rgb = np.dstack([img] * 3)
    np.testing.assert_array_equal(
        extract(rgb, "sift").descriptors, extract(img, "sift").descriptors
    )


@pytest.mark.parametrize(
    ("image", "method", "match"),
    [
        (np.zeros((100, 100), np.float32), "sift", "uint8"),
        (np.zeros((100, 100, 4), np.uint8), "sift", "shape"),
        (np.zeros((8, 100), np.uint8), "sift", "too small"),
        (np.zeros((100, 100), np.uint8), "nope", "unknown feature method 'nope'"),
        (np.zeros((100, 100), np.uint8), "color-sift", "needs an RGB image"),
    ],
)
def test_bad_input_names_the_value(image, method, match):
    with pytest.raises(ValueError, match=match):
        extract(image, method)


def test_keypoints_validate_lengths():
    with pytest.raises(ValueError, match="size_px has 1 entries, xy has 2"):
        Keypoints(np.zeros((2, 2)), [1.0], [0, 0], [0, 0], [0, 0])
    assert "sift" in METHODS
