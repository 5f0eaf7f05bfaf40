"""vision.recognition.ViewIndex: adding and removing views, read access, validation, and the
versioned byte form (round trip, refusal of stale or foreign blobs)."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from tests.vision.recognition_utils import rotated, textured
from vision.errors import VisionCellError
from vision.features import extract
from vision.recognition import FORMAT_VERSION, IndexFormatError, ViewIndex, recognise


@pytest.fixture
def index() -> ViewIndex:
    ix = ViewIndex("sift")
    ix.add("A", textured(0), part="bracket", base="flat")
    ix.add("A", textured(10), viewpoint=2, part="bracket", base="flat")
    ix.add("B", textured(1))
    return ix


def test_add_returns_ids_and_views_are_readable(index):
    assert len(index) == 3
    assert index.models == ("A", "B")
    ids = [v.view_id for v in index.views]
    assert ids == [1, 2, 3]
    v = index.view(2)
    assert (v.model, v.viewpoint, v.part, v.base) == ("A", 2, "bracket", "flat")
    assert len(v.features) > 20
    assert [w.view_id for w in index.views_of("A", viewpoint=1)] == [1]
    assert index.viewpoints_of("A") == (1, 2)
    with pytest.raises(KeyError, match="99"):
        index.view(99)


def test_remove_model_and_view(index):
    assert index.remove_model("A") == 2
    assert index.remove_model("nobody") == 0
    assert index.models == ("B",) and len(index) == 1
    # ids are never reused
    assert index.add("C", textured(2)) == 4
    index.remove_view(4)
    assert len(index) == 1
    assert recognise(index, textured(1)).model == "B"


def test_views_from_precomputed_features_and_given_ids(index):
    feats = extract(textured(3), "sift", max_features=1000)
    vid = index.add("D", feats, view_id=40)
    assert vid == 40 and index.view(40).features is feats
    assert index.add("D", textured(4)) == 41
    with pytest.raises(ValueError, match="already in the index"):
        index.add("D", feats, view_id=40)
    with pytest.raises(ValueError, match="method 'orb'"):
        index.add("D", extract(textured(3), "orb"))
    assert recognise(index, rotated(textured(3), 12)).model == "D"


@pytest.mark.parametrize(
    ("args", "kwargs", "message"),
    [
        (("", None), {}, "model must be"),
        ((3, None), {}, "model must be"),
        (("x" * 201, None), {}, "at most 200"),
        (("A", None), {"viewpoint": 0}, "viewpoint"),
        (("A", None), {"viewpoint": False}, "viewpoint"),
        (("A", None), {"viewpoint": 2.0}, "viewpoint"),
        (("A", None), {"part": ""}, "part must be"),
        (("A", None), {"view_id": -1}, "view_id"),
        (("A", None), {"mask": np.ones((3, 3), bool)}, "mask shape"),
        (("A", np.zeros((160, 160), np.int16)), {}, "uint8"),
        (("A", np.zeros((160, 160, 2), np.uint8)), {}, "shape"),
        (("A", np.full((160, 160), 128, np.uint8)), {}, "too few"),
    ],
)
def test_bad_views_are_refused_and_leave_the_index_unchanged(index, args, kwargs, message):
    model, image = args
    image = textured(5) if image is None else image
    with pytest.raises(ValueError, match=message):
        index.add(model, image, **kwargs)
    assert len(index) == 3


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"method": "nope"}, "unknown feature method"),
        ({"max_features": 0}, "max_features"),
        ({"max_features": True}, "max_features"),
        ({"geometry": "projective"}, "geometry"),
        ({"feature_options": {"mask": 1}}, "must not set"),
    ],
)
def test_bad_index_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ViewIndex(**kwargs)


def test_bytes_round_trip_keeps_views_and_results(index):
    blob = index.to_bytes()
    copy = ViewIndex.from_bytes(blob)
    assert len(copy) == len(index) and copy.models == index.models
    for a, b in zip(index.views, copy.views, strict=True):
        assert (a.view_id, a.model, a.viewpoint, a.part, a.base) == (
            b.view_id,
            b.model,
            b.viewpoint,
            b.part,
            b.base,
        )
        np.testing.assert_array_equal(a.features.descriptors, b.features.descriptors)
        np.testing.assert_array_equal(a.features.keypoints.xy, b.features.keypoints.xy)
        assert a.features.version == b.features.version
    q = rotated(textured(0), 20)
    ra, rb = recognise(index, q), recognise(copy, q)
    assert (ra.decision, ra.model, ra.view_id) == (rb.decision, rb.model, rb.view_id)
    assert ra.score == pytest.approx(rb.score, abs=0.05)
    assert copy.add("E", textured(6)) == 4  # the next id survives the round trip


def test_empty_index_round_trip():
    copy = ViewIndex.from_bytes(ViewIndex("orb").to_bytes())
    assert len(copy) == 0 and copy.method == "orb"


def _rewrite_header(blob: bytes, **changes) -> bytes:
    with np.load(io.BytesIO(blob)) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(bytes(arrays["header"]).decode())
    header.update(changes)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def test_stale_version_is_refused_with_a_clear_error(index):
    blob = _rewrite_header(index.to_bytes(), version=FORMAT_VERSION + 1)
    with pytest.raises(IndexFormatError, match="version") as err:
        ViewIndex.from_bytes(blob)
    assert isinstance(err.value, VisionCellError)
    assert err.value.code == "bad_view_index"


@pytest.mark.parametrize(
    "blob",
    [b"", b"not an index", extract(textured(1), "sift").to_bytes()],
)
def test_foreign_blobs_are_refused(blob):
    with pytest.raises(IndexFormatError):
        ViewIndex.from_bytes(blob)


def test_foreign_format_and_corrupt_counts_are_refused(index):
    with pytest.raises(IndexFormatError, match="format"):
        ViewIndex.from_bytes(_rewrite_header(index.to_bytes(), format="something-else"))
    with pytest.raises(IndexFormatError, match="corrupt"):
        ViewIndex.from_bytes(_rewrite_header(index.to_bytes(), views=[]))
    with pytest.raises(IndexFormatError, match="bytes"):
        ViewIndex.from_bytes("text")


@pytest.mark.parametrize("method", ["sift", "surf"])
def test_features_in_a_mask_are_those_of_the_whole_image(method, monkeypatch):
    """Extraction inside a mask crops the image round it (speed); the keypoints must be the
    whole image's, in the whole image's coordinates, and their descriptors too but for large
    keypoints near the crop's edge."""
    import vision.recognition.index as vi

    img = np.vstack([np.hstack([textured(s, 160) for s in range(r, r + 4)]) for r in (0, 4, 8)])
    mask = np.zeros(img.shape, bool)
    mask[203:341, 251:397] = True  # off the octave grid on purpose
    ix = ViewIndex(method)
    assert vi._mask_crop(mask) is not None  # the crop path is taken
    cropped = ix.features(img, mask=mask)
    monkeypatch.setattr(vi, "CROP_METHODS", frozenset())
    whole = ix.features(img, mask=mask)
    assert len(whole) >= 20
    assert cropped.image_shape == whole.image_shape == (480, 640)
    # Same place, size and orientation (SIFT gives a place one keypoint per orientation).
    kw, kc = whole.keypoints, cropped.keypoints
    d = (
        np.linalg.norm(kw.xy[:, None] - kc.xy[None], axis=2)
        + np.abs(kw.size_px[:, None] - kc.size_px[None])
        + np.abs(np.angle(np.exp(1j * (kw.angle_rad[:, None] - kc.angle_rad[None]))))
    )
    near = d.argmin(axis=1)
    same = d[np.arange(len(whole)), near] < 1e-3
    assert same.mean() >= 0.9, same.mean()
    dw = whole.descriptors[same].astype(np.float64)
    dc = cropped.descriptors[near[same]].astype(np.float64)
    identical = np.abs(dw - dc).max(axis=1) <= 1e-3 * max(1.0, np.abs(dw).max())
    # The others are large keypoints whose window and coarse-octave blur meet the crop's edge.
    assert identical.mean() >= 0.8, identical.mean()
    xy = cropped.keypoints.xy
    assert mask[np.round(xy[:, 1]).astype(int), np.round(xy[:, 0]).astype(int)].mean() > 0.95
