"""Procedural textures for the simulated cell, drawn with numpy and OpenCV at build time.

All images are uint8 RGB, drawn "as seen": row 0 at the top.  :func:`png_bytes` encodes one
for MuJoCo, flipping it so that the mesh convention of :mod:`robot.sim.meshes` (``v`` up)
holds; nothing is written to disk and no binary file is committed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Atlas",
    "charuco_image",
    "chessboard_image",
    "floor_image",
    "label_tile",
    "metal_tile",
    "png_bytes",
    "rim_face_image",
    "tread_image",
    "tyre_image",
]

RGB = tuple[int, int, int]
Image = NDArray[np.uint8]


def png_bytes(image: Image) -> bytes:
    """PNG-encode an RGB image for MuJoCo (rows flipped: MuJoCo puts PNG row 0 at v = 0)."""
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must be uint8 (H, W, 3), got {image.dtype} {image.shape}")
    ok, buf = cv2.imencode(
        ".png", cv2.cvtColor(np.ascontiguousarray(image[::-1]), cv2.COLOR_RGB2BGR)
    )
    if not ok:  # pragma: no cover - OpenCV always encodes uint8 RGB
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def _noise(
    shape: tuple[int, int], rng: np.random.Generator, sigma: float, blur: int
) -> NDArray[np.float32]:
    n = rng.normal(0.0, sigma, size=shape).astype(np.float32)
    if blur > 1:
        n = np.asarray(cv2.GaussianBlur(n, (0, 0), blur), dtype=np.float32)
        n *= sigma / max(float(n.std()), 1e-6)
    return n


def _finish(img_f: NDArray[np.float32], size: tuple[int, int] | None = None) -> Image:
    out = np.clip(img_f, 0, 255).astype(np.uint8)
    if size is not None:
        out = np.asarray(cv2.resize(out, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    return out


# -- wheels ----------------------------------------------------------------------------------
def _spoke_polygon(
    c: float, angle: float, r0: float, r1: float, w0: float, w1: float, sweep: float
) -> NDArray[np.int32]:
    """Outline of one spoke from radius r0 to r1 (pixels), widths w0 -> w1, swept by ``sweep`` rad."""
    t = np.linspace(0.0, 1.0, 12)
    r = r0 + (r1 - r0) * t
    a = angle + sweep * t**1.5
    w = w0 + (w1 - w0) * t
    left = np.stack(
        [c + r * np.cos(a) - w / 2 * np.sin(a), c - r * np.sin(a) - w / 2 * np.cos(a)], 1
    )
    right = np.stack(
        [c + r * np.cos(a) + w / 2 * np.sin(a), c - r * np.sin(a) + w / 2 * np.cos(a)], 1
    )
    return np.round(np.concatenate([left, right[::-1]]) * 4).astype(np.int32)


def rim_face_image(
    *,
    spokes: int,
    style: str,
    bolts: int,
    rim_rgb: RGB,
    cap_text: str = "",
    size_px: int = 512,
    seed: int = 0,
) -> Image:
    """The face of a rim seen from above (outer edge of the rim = the image's inscribed circle).

    Parameters
    ----------
    spokes : int
        Number of spokes (or of ventilation holes for ``style="holes"``).
    style : {"straight", "curved", "split", "twin", "holes"}
        Spoke shape: straight tapered, curved (swept), Y-split near the rim, pairs of thin
        spokes, or a steel disc with round holes.
    bolts : int
        Wheel bolts on the bolt circle.
    rim_rgb : tuple of 3 ints
        Paint or alloy colour.
    cap_text : str
        One or two letters on the centre cap.
    """
    styles = ("straight", "curved", "split", "twin", "holes")
    if style not in styles:
        raise ValueError(f"style must be one of {styles}, got {style!r}")
    if spokes < 3 or bolts < 3:
        raise ValueError(f"spokes and bolts must be >= 3, got spokes={spokes}, bolts={bolts}")
    rng = np.random.default_rng(seed)
    S = 2 * size_px  # draw at twice the size, then reduce (anti-aliasing)
    c = S / 2.0
    R = S / 2.0
    img = np.zeros((S, S, 3), np.float32)
    img[:] = (22, 22, 25)  # openings: the dark inside of the wheel
    # Radial shading and brushed-metal noise of the alloy.
    yy, xx = np.mgrid[0:S, 0:S].astype(np.float32)
    rr = np.hypot(xx - c, yy - c) / R
    alloy = np.empty_like(img)
    shade = 0.75 + 0.35 * np.clip(1.0 - rr, 0, 1) + _noise((S, S), rng, 0.04, 3)
    for k in range(3):
        alloy[..., k] = rim_rgb[k] * shade
    mask = np.zeros((S, S), np.uint8)
    shift = 2  # cv2 fixed-point drawing: coordinates * 4
    cc = (int(c * 4), int(c * 4))
    cv2.circle(mask, cc, int(R * 0.995 * 4), 255, -1, cv2.LINE_AA, shift)
    cv2.circle(mask, cc, int(R * 0.86 * 4), 0, -1, cv2.LINE_AA, shift)  # the rim lip ring
    if style == "holes":
        cv2.circle(mask, cc, int(R * 0.86 * 4), 255, -1, cv2.LINE_AA, shift)
        for i in range(spokes):
            a = 2 * math.pi * i / spokes + math.pi / spokes
            p = (int((c + 0.6 * R * math.cos(a)) * 4), int((c - 0.6 * R * math.sin(a)) * 4))
            cv2.circle(mask, p, int(0.13 * R * 4), 0, -1, cv2.LINE_AA, shift)
    else:
        r0, r1 = 0.2 * R, 0.9 * R
        for i in range(spokes):
            a = 2 * math.pi * i / spokes
            if style == "straight":
                polys = [_spoke_polygon(c, a, r0, r1, 0.16 * R, 0.09 * R, 0.0)]
            elif style == "curved":
                polys = [_spoke_polygon(c, a, r0, r1, 0.12 * R, 0.07 * R, 0.55)]
            elif style == "twin":
                d = 0.07
                polys = [
                    _spoke_polygon(c, a - d, r0, r1, 0.05 * R, 0.04 * R, 0.0),
                    _spoke_polygon(c, a + d, r0, r1, 0.05 * R, 0.04 * R, 0.0),
                ]
            else:  # split: one trunk, two branches to the rim
                polys = [
                    _spoke_polygon(c, a, r0, 0.55 * R, 0.13 * R, 0.10 * R, 0.0),
                    _spoke_polygon(c, a, 0.5 * R, r1, 0.06 * R, 0.05 * R, 0.35),
                    _spoke_polygon(c, a, 0.5 * R, r1, 0.06 * R, 0.05 * R, -0.35),
                ]
            cv2.fillPoly(mask, polys, 255, cv2.LINE_AA, shift)
    cv2.circle(mask, cc, int(0.27 * R * 4), 255, -1, cv2.LINE_AA, shift)  # hub
    m = (mask.astype(np.float32) / 255.0)[..., None]
    img = img * (1 - m) + alloy * m
    # Centre cap, bolts with bright rings, and a thin highlight on the lip.
    cap = tuple(float(v) * 0.55 for v in rim_rgb)
    cv2.circle(img, cc, int(0.12 * R * 4), cap, -1, cv2.LINE_AA, shift)
    cv2.circle(img, cc, int(0.12 * R * 4), (200, 200, 205), 3, cv2.LINE_AA, shift)
    for i in range(bolts):
        a = 2 * math.pi * i / bolts + math.pi / 2
        p = (int((c + 0.19 * R * math.cos(a)) * 4), int((c - 0.19 * R * math.sin(a)) * 4))
        cv2.circle(img, p, int(0.035 * R * 4), (235, 235, 238), -1, cv2.LINE_AA, shift)
        cv2.circle(img, p, int(0.022 * R * 4), (40, 40, 44), -1, cv2.LINE_AA, shift)
    cv2.circle(img, cc, int(0.93 * R * 4), (250, 250, 252), 2, cv2.LINE_AA, shift)
    if cap_text:
        scale = 0.0035 * S / max(len(cap_text), 1)
        (tw, th), _ = cv2.getTextSize(cap_text, cv2.FONT_HERSHEY_DUPLEX, scale, 3)
        cv2.putText(
            img,
            cap_text,
            (int(c - tw / 2), int(c + th / 2)),
            cv2.FONT_HERSHEY_DUPLEX,
            scale,
            (240, 240, 240),
            3,
            cv2.LINE_AA,
        )
    return _finish(img, (size_px, size_px))


def tyre_image(
    *,
    sidewall_text: str,
    bands: Sequence[tuple[float, float]],
    tread_style: str = "blocks",
    width_px: int = 1024,
    height_px: int = 256,
    seed: int = 0,
) -> Image:
    """The unrolled rubber of a tyre except its tread: ``u`` around, ``v`` along the profile.

    Parameters
    ----------
    sidewall_text : str
        Lettering on the upper sidewall (written twice around, as on real tyres).
    bands : sequence of 3 ``(v0, v1)``
        ``v`` ranges of the upper sidewall, the shoulders and the lower sidewall.
    tread_style : {"blocks", "ribs"}
        Pattern continued over the shoulders.
    """
    if len(bands) != 3:
        raise ValueError(f"bands must give 3 (v0, v1) ranges, got {len(bands)}")
    rng = np.random.default_rng(seed)
    W, H = width_px, height_px
    img = np.empty((H, W, 3), np.float32)
    img[:] = (38, 38, 40)
    img += _noise((H, W), rng, 3.0, 1)[..., None]

    def rows(v0: float, v1: float) -> tuple[int, int]:
        # Image row 0 is v = 1 (see png_bytes).
        return round((1.0 - v1) * H), round((1.0 - v0) * H)

    s0, s1 = rows(*bands[0])
    band_h = s1 - s0
    if sidewall_text and band_h > 8:
        strip = np.zeros((band_h, W // 2, 3), np.float32)
        strip[:] = (38, 38, 40)
        scale = 0.62 * band_h / 30.0
        (tw, th), _ = cv2.getTextSize(sidewall_text, cv2.FONT_HERSHEY_DUPLEX, scale, 2)
        scale *= min(1.0, 0.9 * (W // 2) / max(tw, 1))
        (tw, th), _ = cv2.getTextSize(sidewall_text, cv2.FONT_HERSHEY_DUPLEX, scale, 2)
        org = ((W // 2 - tw) // 2, (band_h + th) // 2)
        cv2.putText(
            strip,
            sidewall_text,
            org,
            cv2.FONT_HERSHEY_DUPLEX,
            scale,
            (150, 150, 150),
            2,
            cv2.LINE_AA,
        )
        # u runs counter-clockwise seen from above, so text written left to right would
        # read backwards: mirror it along u.  Image rows already run outwards (v up), so the
        # letters' tops point to the tread, as on real tyres.
        strip = strip[:, ::-1]
        img[s0:s1] = np.concatenate([strip, strip], axis=1)[:, :W]
        img[s0 : s0 + 2] += 20  # rim protector ridges
        img[s1 - 2 : s1] += 20
    h0, h1 = rows(*bands[1])
    _tread_pattern(img[h0:h1], tread_style)
    return _finish(img)


def _tread_pattern(region: NDArray[np.float32], style: str) -> None:
    h, w = region.shape[:2]
    if style == "blocks":
        for x in range(0, w, 16):
            cv2.line(region, (x, 0), (x + 8, h // 2), (18, 18, 19), 3)
            cv2.line(region, (x + 8, h // 2), (x, h), (18, 18, 19), 3)
    else:
        for y in np.linspace(0.2, 0.8, 4):
            region[int(y * h) : int(y * h) + 3] = (16, 16, 17)


def tread_image(
    *,
    tread_text: str = "",
    band_rgb: RGB | None = None,
    tread_style: str = "blocks",
    width_px: int = 1024,
    height_px: int = 96,
    seed: int = 0,
) -> Image:
    """The tread (the tyre's outer cylinder), drawn upright as seen from outside.

    A separate texture from :func:`tyre_image`, so that nothing of the tread (a coloured
    band, lettering) bleeds into what is seen from above through texture filtering.  On the
    mesh ``u`` grows to the right of a viewer outside and ``v`` grows downwards.
    """
    rng = np.random.default_rng(seed + 1)
    W, H = width_px, height_px
    img = np.empty((H, W, 3), np.float32)
    img[:] = (38, 38, 40)
    img += _noise((H, W), rng, 3.0, 1)[..., None]
    _tread_pattern(img, tread_style)
    if band_rgb is not None:
        img[int(0.3 * H) : int(0.7 * H)] = band_rgb
    if tread_text:
        scale = 0.3 * H / 22.0
        (_, text_h), _ = cv2.getTextSize(tread_text, cv2.FONT_HERSHEY_DUPLEX, scale, 2)
        for x in range(0, W, W // 4):
            cv2.putText(
                img,
                tread_text,
                (x + 20, (H + text_h) // 2),
                cv2.FONT_HERSHEY_DUPLEX,
                scale,
                (240, 240, 240),
                2,
                cv2.LINE_AA,
            )
    return _finish(img)[::-1].copy()  # rows: v grows downwards on the mesh


# -- parts -----------------------------------------------------------------------------------
class Atlas:
    """A square grid of tiles in one texture; :meth:`uv` gives a tile's rectangle for meshes."""

    def __init__(self, tiles_per_side: int, tile_px: int = 128) -> None:
        if tiles_per_side < 1 or tile_px < 8:
            raise ValueError(
                f"need tiles_per_side >= 1 and tile_px >= 8, got {tiles_per_side}, {tile_px}"
            )
        self.n = tiles_per_side
        self.px = tile_px
        self.image = np.zeros((tiles_per_side * tile_px, tiles_per_side * tile_px, 3), np.uint8)
        self._next = 0

    def add(self, tile: Image) -> tuple[float, float, float, float]:
        """Place ``tile`` (resized to the tile size) and return its ``(u0, v0, u1, v1)``."""
        if self._next >= self.n * self.n:
            raise ValueError(f"atlas is full ({self.n * self.n} tiles)")
        i, j = divmod(self._next, self.n)
        self._next += 1
        t = cv2.resize(tile, (self.px, self.px), interpolation=cv2.INTER_AREA)
        self.image[i * self.px : (i + 1) * self.px, j * self.px : (j + 1) * self.px] = t
        # Half a texel inset so that filtering does not bleed in the neighbours.
        e = 0.5 / (self.n * self.px)
        u0, u1 = j / self.n + e, (j + 1) / self.n - e
        v1, v0 = 1.0 - i / self.n - e, 1.0 - (i + 1) / self.n + e
        return (u0, v0, u1, v1)


def metal_tile(
    rgb: RGB, *, seed: int = 0, size_px: int = 128, brushed: bool = True, screws: int = 0
) -> Image:
    """Painted or brushed metal, optionally with ``screws`` screw heads in the corners."""
    rng = np.random.default_rng(seed)
    n = rng.normal(0.0, 1.0, (size_px, size_px)).astype(np.float32)
    n = cv2.blur(n, (15, 1)) * 6.0 if brushed else cv2.GaussianBlur(n, (0, 0), 2) * 6.0
    img = np.empty((size_px, size_px, 3), np.float32)
    for k in range(3):
        img[..., k] = rgb[k] + n
    corners = [(0.15, 0.15), (0.85, 0.15), (0.85, 0.85), (0.15, 0.85)]
    for x, y in corners[:screws]:
        p = (int(x * size_px), int(y * size_px))
        cv2.circle(img, p, size_px // 16, (60, 60, 64), -1, cv2.LINE_AA)
        cv2.circle(img, p, size_px // 16, (200, 200, 205), 1, cv2.LINE_AA)
        cv2.line(img, (p[0] - size_px // 24, p[1]), (p[0] + size_px // 24, p[1]), (20, 20, 22), 1)
    return _finish(img)


def label_tile(
    text: str,
    *,
    bg: RGB,
    fg: RGB,
    plate: RGB | None = None,
    seed: int = 0,
    size_px: int = 128,
    holes: int = 0,
    stripes: bool = False,
) -> Image:
    """A painted face with a name plate (``text``), optional dark holes and hazard stripes."""
    img = metal_tile(bg, seed=seed, size_px=size_px, brushed=False).astype(np.float32)
    if stripes:
        for x in range(-size_px, size_px, 24):
            pts = np.array(
                [
                    [x, size_px],
                    [x + 12, size_px],
                    [x + 12 + 24, size_px - 24],
                    [x + 24, size_px - 24],
                ]
            )
            cv2.fillPoly(img, [pts.astype(np.int32)], (235, 190, 20), cv2.LINE_AA)
    if holes:
        for i in range(holes):
            p = (int((i + 0.5) * size_px / holes), int(0.3 * size_px))
            cv2.circle(img, p, size_px // (3 * holes) + 2, (15, 15, 17), -1, cv2.LINE_AA)
            cv2.circle(img, p, size_px // (3 * holes) + 2, (170, 170, 175), 1, cv2.LINE_AA)
    if text:
        y0 = int(0.55 * size_px)
        if plate is not None:
            cv2.rectangle(img, (8, y0), (size_px - 8, y0 + size_px // 4), plate, -1, cv2.LINE_AA)
        scale = (
            0.9
            * (size_px - 24)
            / max(cv2.getTextSize(text, cv2.FONT_HERSHEY_DUPLEX, 1.0, 2)[0][0], 1)
        )
        (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_DUPLEX, scale, 2)
        cv2.putText(
            img,
            text,
            ((size_px - tw) // 2, y0 + size_px // 8 + th // 2),
            cv2.FONT_HERSHEY_DUPLEX,
            scale,
            fg,
            2,
            cv2.LINE_AA,
        )
    return _finish(img)


# -- the cell --------------------------------------------------------------------------------
def floor_image(*, size_px: int = 512, seed: int = 0) -> Image:
    """Speckled concrete (one tile; the floor material repeats it)."""
    rng = np.random.default_rng(seed)
    base = 150.0 + _noise((size_px, size_px), rng, 9.0, 4) + _noise((size_px, size_px), rng, 4.0, 1)
    img = np.repeat(base[..., None], 3, axis=2) * np.array([1.0, 0.99, 0.96], np.float32)
    return _finish(img)


# -- calibration boards ----------------------------------------------------------------------
def chessboard_image(
    cols: int, rows: int, *, px_per_square: int = 48, margin_squares: float = 1.0
) -> Image:
    """A chessboard with ``cols x rows`` inner corners and a white margin.

    The top-left square is black; the board has ``cols + 1`` by ``rows + 1`` squares.  Square
    edges fall exactly on texel boundaries.
    """
    if cols < 2 or rows < 2:
        raise ValueError(f"cols and rows (inner corners) must be >= 2, got {cols}, {rows}")
    m = round(margin_squares * px_per_square)
    W = (cols + 1) * px_per_square + 2 * m
    H = (rows + 1) * px_per_square + 2 * m
    img = np.full((H, W, 3), 245, np.uint8)
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                y, x = m + j * px_per_square, m + i * px_per_square
                img[y : y + px_per_square, x : x + px_per_square] = 12
    return img


def charuco_image(
    board: object, squares_x: int, squares_y: int, *, px_per_square: int = 64, margin_px: int = 32
) -> Image:
    """Render an OpenCV ``cv2.aruco.CharucoBoard`` with ``generateImage`` (RGB, exact square pitch)."""
    size = (squares_x * px_per_square + 2 * margin_px, squares_y * px_per_square + 2 * margin_px)
    grey = board.generateImage(size, marginSize=margin_px, borderBits=1)  # type: ignore[attr-defined]
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB)
