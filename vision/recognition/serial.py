"""Byte form of a :class:`vision.recognition.ViewIndex` (the database's blob): a compressed
``.npz`` of concatenated keypoints and descriptors with a JSON header naming the format and
its version; anything else is refused with :class:`IndexFormatError`."""

from __future__ import annotations

import io
import json
from typing import TYPE_CHECKING

import numpy as np

from vision.errors import VisionCellError
from vision.features import Features, Keypoints
from vision.recognition.colour import SIGNATURE_SIZE, check_signature
from vision.recognition.trained import TrainedView, check_viewpoint

if TYPE_CHECKING:
    from vision.recognition.index import ViewIndex

__all__ = ["FORMAT", "FORMAT_VERSION", "IndexFormatError", "dump", "load"]

#: Magic name and version of the byte form; bump the version whenever the layout or the
#: meaning of a stored field changes.
FORMAT = "visioncell.view-index"
FORMAT_VERSION = 2
#: Older versions :func:`load` still reads (1: without colour signatures).
READABLE_VERSIONS = (1, 2)


class IndexFormatError(VisionCellError, ValueError):
    """A serialised index is not one, or was written by another (stale) format version."""

    code = "bad_view_index"


def dump(index: ViewIndex) -> bytes:
    """Serialise ``index`` (views and options, not the ANN structures)."""
    views = index.views
    header = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "method": index.method,
        "max_features": index.max_features,
        "geometry": index.geometry,
        "feature_options": index.feature_options,
        "colour_transfer": index.colour_transfer,
        "min_features": index.min_features,
        "next_id": index.next_id,
        "views": [
            {
                "id": v.view_id,
                "model": v.model,
                "viewpoint": v.viewpoint,
                "part": v.part,
                "base": v.base,
                "n": len(v.features),
                "feature_version": v.features.version,
                "binary": v.features.binary,
                "image_shape": list(v.features.image_shape),
                "colour": v.colour is not None,
                "outline_n": 0 if v.outline is None else len(v.outline),
            }
            for v in views
        ],
    }
    fs = [v.features for v in views]
    kps = [f.keypoints for f in fs]
    dim = fs[0].dim if fs else 0
    dtype = np.uint8 if fs and fs[0].binary else np.float32
    arrays = {
        "header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8),
        "xy": np.concatenate([k.xy for k in kps]) if fs else np.zeros((0, 2)),
        "size_px": np.concatenate([k.size_px for k in kps]) if fs else np.zeros(0),
        "angle_rad": np.concatenate([k.angle_rad for k in kps]) if fs else np.zeros(0),
        "response": np.concatenate([k.response for k in kps]) if fs else np.zeros(0),
        "octave": np.concatenate([k.octave for k in kps]) if fs else np.zeros(0, np.int32),
        "descriptors": (
            np.concatenate([f.descriptors for f in fs]) if fs else np.zeros((0, dim), dtype)
        ),
        "colour": np.array(
            [v.colour for v in views if v.colour is not None], dtype=np.float32
        ).reshape(-1, SIGNATURE_SIZE),
        "outline": np.concatenate(
            [np.zeros((0, 2), np.float32)] + [v.outline for v in views if v.outline is not None]
        ).astype(np.float32),
    }
    buf = io.BytesIO()
    np.savez_compressed(buf, allow_pickle=False, **arrays)
    return buf.getvalue()


def load(cls: type[ViewIndex], blob: bytes) -> ViewIndex:
    """Rebuild an index written by :func:`dump` (``IndexFormatError`` otherwise).

    Fills the new index's view table directly (this module is the index's storage half).
    """
    if not isinstance(blob, bytes | bytearray | memoryview):
        raise IndexFormatError(f"a view index blob must be bytes, got {type(blob).__name__}")
    try:
        with np.load(io.BytesIO(bytes(blob)), allow_pickle=False) as z:
            header = json.loads(bytes(z["header"]).decode())
            data = {k: z[k] for k in z.files if k != "header"}
    except Exception as exc:
        raise IndexFormatError(f"not a serialised view index: {exc}") from exc
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        got = header.get("format") if isinstance(header, dict) else header
        raise IndexFormatError(f"not a serialised view index (format {got!r})")
    if header.get("version") not in READABLE_VERSIONS:
        raise IndexFormatError(
            f"view index format version {header.get('version')!r} is not the supported "
            f"version {FORMAT_VERSION}: retrain the views (or migrate the stored index)"
        )
    try:
        index = cls(
            header["method"],
            max_features=header["max_features"],
            geometry=header["geometry"],
            feature_options=header["feature_options"],
            min_features=header["min_features"],
            colour_transfer=header.get("colour_transfer", "srgb"),
        )
        start = 0
        colours = data.get("colour", np.zeros((0, SIGNATURE_SIZE), np.float32))
        outlines = data.get("outline", np.zeros((0, 2), np.float32))
        n_colour = n_outline = 0
        for v in header["views"]:
            sl = slice(start, start + int(v["n"]))
            start = sl.stop
            kp = Keypoints(
                data["xy"][sl],
                data["size_px"][sl],
                data["angle_rad"][sl],
                data["response"][sl],
                data["octave"][sl],
            )
            f = Features(
                kp,
                data["descriptors"][sl],
                header["method"],
                v["feature_version"],
                bool(v["binary"]),
                tuple(v["image_shape"]),
            )
            vid = int(v["id"])
            colour = outline = None
            if v.get("colour", False):
                colour = check_signature(colours[n_colour])
                n_colour += 1
                k = int(v.get("outline_n", 0))
                outline = outlines[n_outline : n_outline + k]
                if len(outline) != k:
                    raise ValueError("outline points missing")
                n_outline += k
            index._views[vid] = TrainedView(
                vid,
                v["model"],
                check_viewpoint(v["viewpoint"]),
                v["part"],
                v["base"],
                f,
                colour,
                outline,
            )
        if start != len(data["descriptors"]):
            raise ValueError("descriptor count does not match the views")
        if n_colour != len(colours) or n_outline != len(outlines):
            raise ValueError("colour signature or outline count does not match the views")
        index._next_id = max([int(header["next_id"]), *[k + 1 for k in index._views]])
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise IndexFormatError(f"corrupt view index: {exc}") from exc
    return index
