"""Procedural triangle meshes with texture coordinates, for the simulated cell's objects.

Every mesh is built in code (no mesh files): surfaces of revolution for wheels, tyres and
round parts, and boxes whose six faces map to tiles of a texture atlas.  Vertices are in
metres in the mesh's own frame; texture coordinates follow OpenGL (``u`` to the right,
``v`` up, origin at the bottom-left of the image as MuJoCo samples PNG textures).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Mesh", "box", "concat", "disc", "revolve", "transformed"]


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh with per-vertex normals and texture coordinates.

    Attributes
    ----------
    vertices : ndarray of shape (N, 3)
        Positions in metres.
    normals : ndarray of shape (N, 3)
        Unit outward normals.
    uv : ndarray of shape (N, 2)
        Texture coordinates in [0, 1].
    faces : ndarray of shape (M, 3), int
        Counter-clockwise (seen from outside) vertex indices.
    """

    vertices: NDArray[np.float64]
    normals: NDArray[np.float64]
    uv: NDArray[np.float64]
    faces: NDArray[np.int64]

    def __post_init__(self) -> None:
        n = self.vertices.shape[0]
        if self.vertices.shape != (n, 3) or self.normals.shape != (n, 3):
            raise ValueError(
                f"vertices and normals must have shape (N, 3), got {self.vertices.shape} "
                f"and {self.normals.shape}"
            )
        if self.uv.shape != (n, 2):
            raise ValueError(f"uv must have shape ({n}, 2), got {self.uv.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must have shape (M, 3), got {self.faces.shape}")
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= n):
            raise ValueError(
                f"faces index outside [0, {n}), got [{self.faces.min()}, {self.faces.max()}]"
            )

    @property
    def bounds(self) -> NDArray[np.float64]:
        """``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, metres."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def revolve(
    profile_rz: ArrayLike,
    *,
    segments: int = 64,
    v_range: tuple[float, float] = (0.0, 1.0),
    u_repeat: float = 1.0,
) -> Mesh:
    """Surface of revolution of a polyline about the z axis.

    Each profile segment becomes its own strip with a flat profile normal (sharp edges stay
    sharp); around the axis the normals are smooth.  ``v`` runs along the profile by arc
    length over ``v_range``; ``u`` runs once (``u_repeat`` times) around the axis, with the
    seam duplicated so that the texture wraps.

    Parameters
    ----------
    profile_rz : array_like of shape (P, 2)
        ``(r, z)`` points, metres, ``r >= 0``.  Walk the profile with the outside on the
        left-hand side (r to the right, z up): a closed solid is walked clockwise, e.g. a
        tyre from the bead across the top, down the tread and back along the bottom.
    segments : int
        Facets around the axis.
    v_range : tuple of float
        Texture ``v`` at the first and last profile point.
    u_repeat : float
        How many times the texture wraps around.
    """
    prof = np.asarray(profile_rz, dtype=np.float64)
    if prof.ndim != 2 or prof.shape[1] != 2 or prof.shape[0] < 2:
        raise ValueError(f"profile_rz must have shape (P >= 2, 2), got {prof.shape}")
    if np.any(prof[:, 0] < 0):
        raise ValueError(f"profile radii must be >= 0, got min {prof[:, 0].min()}")
    if segments < 3:
        raise ValueError(f"segments must be >= 3, got {segments}")
    seg_len = np.linalg.norm(np.diff(prof, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg_len)])
    total = arc[-1] if arc[-1] > 0 else 1.0
    v_of = v_range[0] + (v_range[1] - v_range[0]) * arc / total
    theta = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    c, s = np.cos(theta), np.sin(theta)
    verts, norms, uvs, faces = [], [], [], []
    base = 0
    for i in range(prof.shape[0] - 1):
        if seg_len[i] <= 0:
            continue
        (r0, z0), (r1, z1) = prof[i], prof[i + 1]
        dr, dz = (r1 - r0) / seg_len[i], (z1 - z0) / seg_len[i]
        nr, nz = -dz, dr  # the tangent turned counter-clockwise points outside
        for r, z, v in ((r0, z0, v_of[i]), (r1, z1, v_of[i + 1])):
            verts.append(np.stack([r * c, r * s, np.full_like(c, z)], axis=1))
            norms.append(np.stack([nr * c, nr * s, np.full_like(c, nz)], axis=1))
            uvs.append(np.stack([u_repeat * theta / (2.0 * np.pi), np.full_like(c, v)], axis=1))
        k = np.arange(segments)
        a, b = base + k, base + k + 1
        a2, b2 = a + segments + 1, b + segments + 1
        # Counter-clockwise seen from outside for a profile walked with the outside on its
        # left: (a, a2, b) and (b, a2, b2), where a2, b2 lie one profile point further.
        faces.append(np.stack([a, a2, b], axis=1))
        faces.append(np.stack([b, a2, b2], axis=1))
        base += 2 * (segments + 1)
    return Mesh(
        np.concatenate(verts),
        _unit(np.concatenate(norms)),
        np.concatenate(uvs),
        np.concatenate(faces).astype(np.int64),
    )


def disc(radius: float, z: float, *, segments: int = 64, up: bool = True) -> Mesh:
    """A flat disc at height ``z`` with planar texture coordinates.

    ``u = 0.5 + x / (2 radius)``, ``v = 0.5 + y / (2 radius)``: a square texture drawn as
    seen from above (+z) lands on the disc unrotated and unmirrored.
    """
    if not radius > 0:
        raise ValueError(f"radius must be positive, got {radius!r}")
    theta = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(theta), radius * np.sin(theta), np.full(segments, z)], axis=1)
    verts = np.concatenate([[[0.0, 0.0, z]], ring])
    uv = 0.5 + verts[:, :2] / (2.0 * radius)
    k = np.arange(segments)
    nxt = (k + 1) % segments
    faces = np.stack([np.zeros(segments, dtype=np.int64), k + 1, nxt + 1], axis=1)
    if not up:
        faces = faces[:, ::-1]
    normal = np.array([0.0, 0.0, 1.0 if up else -1.0])
    return Mesh(verts, np.tile(normal, (segments + 1, 1)), uv, faces)


#: Face order of :func:`box` tiles: +x, -x, +y, -y, +z, -z.
BOX_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def box(
    size_xyz: ArrayLike,
    tiles: Sequence[tuple[float, float, float, float]],
    *,
    center: ArrayLike = (0.0, 0.0, 0.0),
) -> Mesh:
    """An axis-aligned box whose faces show tiles of a texture atlas.

    Parameters
    ----------
    size_xyz : array_like of 3 floats
        Full edge lengths, metres.
    tiles : sequence of 6 ``(u0, v0, u1, v1)``
        Atlas rectangle per face in :data:`BOX_FACES` order.  Looking at a face from outside
        with z up (or, for the top and bottom, with +y up for the top and -y up for the
        bottom), ``u`` runs to the right and ``v`` upwards.
    center : array_like of 3 floats
        Centre of the box, metres.
    """
    sx, sy, sz = (float(v) / 2.0 for v in np.asarray(size_xyz, dtype=np.float64))
    if min(sx, sy, sz) <= 0:
        raise ValueError(f"size_xyz must be positive, got {list(size_xyz)}")  # type: ignore[arg-type]
    if len(tiles) != 6:
        raise ValueError(f"tiles must have 6 entries (+x, -x, +y, -y, +z, -z), got {len(tiles)}")
    # Per face: normal, right and up directions (as seen from outside).
    frames = [
        ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
        ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),
        ((0, 1, 0), (-1, 0, 0), (0, 0, 1)),
        ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        ((0, 0, -1), (1, 0, 0), (0, -1, 0)),
    ]
    half = np.array([sx, sy, sz])
    verts, norms, uvs, faces = [], [], [], []
    for f, (axes, (u0, v0, u1, v1)) in enumerate(zip(frames, tiles, strict=True)):
        n, r, u = (np.array(a, dtype=np.float64) for a in axes)
        c0 = n * half
        hr, hu = np.abs(r) @ half, np.abs(u) @ half
        corners = [
            c0 - r * hr - u * hu,
            c0 + r * hr - u * hu,
            c0 + r * hr + u * hu,
            c0 - r * hr + u * hu,
        ]
        verts.extend(corners)
        norms.extend([n] * 4)
        uvs.extend([(u0, v0), (u1, v0), (u1, v1), (u0, v1)])
        b = 4 * f
        faces.extend([(b, b + 1, b + 2), (b, b + 2, b + 3)])
    return Mesh(
        np.asarray(verts) + np.asarray(center, dtype=np.float64),
        np.asarray(norms, dtype=np.float64),
        np.asarray(uvs, dtype=np.float64),
        np.asarray(faces, dtype=np.int64),
    )


def transformed(mesh: Mesh, T: ArrayLike) -> Mesh:
    """``mesh`` moved by the 4x4 rigid transform ``T``."""
    Ta = np.asarray(T, dtype=np.float64)
    if Ta.shape != (4, 4):
        raise ValueError(f"T must have shape (4, 4), got {Ta.shape}")
    R, t = Ta[:3, :3], Ta[:3, 3]
    return Mesh(mesh.vertices @ R.T + t, mesh.normals @ R.T, mesh.uv.copy(), mesh.faces.copy())


def concat(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh holding all of ``meshes`` (they must share one texture)."""
    if not meshes:
        raise ValueError("concat needs at least one mesh")
    offsets = np.cumsum([0] + [m.vertices.shape[0] for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.normals for m in meshes]),
        np.concatenate([m.uv for m in meshes]),
        np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)]),
    )
