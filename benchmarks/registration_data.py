"""Image pairs with a known homography for the registration benchmark and its tests.

* Oxford sequences (Mikolajczyk et al., IJCV 2005) under ``DATA/registration/oxford``:
  graf (viewpoint 20..60 deg), boat (zoom + rotation), bikes (blur); pairs img1 -> imgN with
  the published ``H1toNp``.
* Illumination changes of scikit-image's colour photos, each under a documented model
  (:func:`apply_illumination`) and a known mild warp (:data:`MILD_WARP`).
* Synthetic rescaling of one image (chapter Figure 12, equation 14).
* Simulated views of a car wheel on the belt (chapter Figure 15: rotated, translated and
  scaled tyre images), rendered by the MuJoCo cell with an ideal lens; the ground truth is the
  homography induced by the wheel's top plane, computed from the simulator's true poses.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from vision.errors import CameraError
from vision.sources import read_rgb

__all__ = [
    "GRAF_ANGLES_DEG",
    "ILLUMINATION_MODELS",
    "MILD_WARP",
    "ImagePair",
    "apply_illumination",
    "illumination_pairs",
    "oxford_pairs",
    "scale_pairs",
    "sim_wheel_pairs",
    "skimage_photo",
]

#: Viewpoint angle of graf img2..img6 relative to img1 (Mikolajczyk et al. 2005).
GRAF_ANGLES_DEG = {2: 20, 3: 30, 4: 40, 5: 50, 6: 60}
OXFORD_SEQUENCES = ("graf", "boat", "bikes")


@dataclass(frozen=True, eq=False)
class ImagePair:
    """Two images of one scene and the homography mapping pixels of ``a`` to ``b``.

    Attributes
    ----------
    sequence : str
        Group name (``"graf"``, ``"illumination"``, ``"scale"``, ``"sim-wheel"`` ...).
    name : str
        Pair name, unique within the sequence (``"1-3"``, ``"astronaut/gain"`` ...).
    a, b : ndarray (H, W, 3) uint8
        RGB images.
    H : ndarray (3, 3)
        Ground truth ``x_b ~ H x_a``.
    param : float
        The study's variable: viewpoint angle (deg), scale factor, yaw (deg), image index.
    mask_a : ndarray (H, W) bool or None
        Where in ``a`` the homography holds (None: everywhere).
    note : str
        What the pair shows and how exact its ground truth is.
    """

    sequence: str
    name: str
    a: np.ndarray
    b: np.ndarray
    H: np.ndarray
    param: float = 0.0
    mask_a: np.ndarray | None = None
    note: str = field(default="")


@functools.cache
def _read_rgb(path: Path) -> np.ndarray:
    """The image at ``path`` (RGB), read once per run and shared read-only, so that every pair
    holding it is the same array and the benchmark extracts its features once."""
    try:
        img = read_rgb(path)
    except CameraError as exc:
        raise FileNotFoundError(str(exc)) from exc
    img.setflags(write=False)
    return img


def oxford_pairs(
    data_dir: Path, sequence: str, indices: tuple[int, ...] = (2, 3, 4, 5, 6)
) -> list[ImagePair]:
    """Pairs ``img1 -> imgN`` of an Oxford sequence with their ``H1toNp``.

    Raises
    ------
    FileNotFoundError
        The sequence folder (``data_dir/registration/oxford/<sequence>``) is absent.
    ValueError
        Unknown sequence or index.
    """
    if sequence not in OXFORD_SEQUENCES:
        raise ValueError(f"sequence must be one of {OXFORD_SEQUENCES}, got {sequence!r}")
    bad = [i for i in indices if i not in GRAF_ANGLES_DEG]
    if bad:
        raise ValueError(f"indices must be in 2..6, got {bad}")
    folder = Path(data_dir) / "registration" / "oxford" / sequence
    if not (folder / "img1.png").is_file():
        raise FileNotFoundError(f"{folder} is absent (see ../shared/data/README.md)")
    a = _read_rgb(folder / "img1.png")
    pairs = []
    for n in indices:
        H = np.loadtxt(folder / f"H1to{n}p")
        param = float(GRAF_ANGLES_DEG[n]) if sequence == "graf" else float(n)
        pairs.append(ImagePair(sequence, f"1-{n}", a, _read_rgb(folder / f"img{n}.png"), H, param))
    return pairs


# -- illumination ----------------------------------------------------------------------------
#: Photos of scikit-image used for the illumination tests (colourful, textured).
PHOTOS = ("astronaut", "coffee", "chelsea", "rocket")

#: Mild similarity warp applied to ``b`` in the illumination pairs: 6 deg rotation and 0.9
#: scale about the image centre (so that descriptors are not compared at identical pixels).
MILD_WARP = (6.0, 0.9)

#: name -> parameter of each illumination model (see :func:`apply_illumination`).
ILLUMINATION_MODELS: dict[str, tuple[float, ...]] = {
    "gain": (1.35, 0.95, 0.7),  # per-channel gains R, G, B
    "cast": (0.25,),  # warm colour temperature: R x (1 + k), B x (1 - k)
    "shading": (0.6,),  # horizontal gain ramp from 1 - s/2 to 1 + s/2 (all channels)
    "gamma": (1.6,),  # I' = 255 (I / 255) ^ gamma
}


@functools.cache
def skimage_photo(name: str) -> np.ndarray:
    """A colour photo bundled with scikit-image (RGB uint8), loaded once per run and shared
    read-only (see :func:`_read_rgb`)."""
    from skimage import data

    if name not in PHOTOS:
        raise ValueError(f"photo must be one of {PHOTOS}, got {name!r}")
    img = np.ascontiguousarray(getattr(data, name)()[..., :3]).astype(np.uint8)
    img.setflags(write=False)
    return img


def apply_illumination(image: np.ndarray, model: str, params: tuple[float, ...]) -> np.ndarray:
    """Change the lighting of an RGB image by a documented model.

    * ``"gain"`` ``(gR, gG, gB)``: every channel multiplied by its gain (a diagonal, von Kries
      change of the illuminant's colour and intensity); the log colour ratios of equation 17
      are unchanged up to clipping.
    * ``"cast"`` ``(k,)``: a colour-temperature cast, ``R x (1 + k)``, ``G`` kept, ``B x (1 - k)``
      (``k > 0`` warmer, ``k < 0`` cooler): a special diagonal change.
    * ``"shading"`` ``(s,)``: the same gain for all channels, varying linearly across the image
      from ``1 - s/2`` at the left edge to ``1 + s/2`` at the right (a light to one side):
      grey levels change non-uniformly, colour ratios do not.
    * ``"gamma"`` ``(g,)``: ``255 (I / 255)^g`` per channel: a non-linear response that changes
      contrast and scales the log colour ratios by ``g``.

    Results are rounded and clipped to [0, 255].
    """
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must be RGB uint8 (H, W, 3), got {image.dtype} {image.shape}")
    if model not in ILLUMINATION_MODELS:
        raise ValueError(f"model must be one of {tuple(ILLUMINATION_MODELS)}, got {model!r}")
    f = image.astype(np.float64)
    if model == "gain":
        if len(params) != 3:
            raise ValueError(f"gain needs 3 channel gains, got {params!r}")
        out = f * np.asarray(params, dtype=np.float64)[None, None, :]
    elif model == "cast":
        (k,) = params
        out = f * np.array([1.0 + k, 1.0, 1.0 - k])[None, None, :]
    elif model == "shading":
        (s,) = params
        w = image.shape[1]
        ramp = 1.0 + s * (np.arange(w) / max(w - 1, 1) - 0.5)
        out = f * ramp[None, :, None]
    else:
        (g,) = params
        out = 255.0 * (f / 255.0) ** g
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def similarity_about_centre(shape: tuple[int, int], angle_deg: float, scale: float) -> np.ndarray:
    """3x3 rotation by ``angle_deg`` (counter-clockwise on screen) and scaling about the centre."""
    h, w = shape
    A = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle_deg, scale)
    return np.vstack([A, [0.0, 0.0, 1.0]])


def _warp(image: np.ndarray, H: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    return cv2.warpPerspective(image, H, size, flags=cv2.INTER_LINEAR)


def illumination_pairs(
    photos: tuple[str, ...] = PHOTOS, data_dir: Path | None = None
) -> list[ImagePair]:
    """Each photo against itself under each illumination model and :data:`MILD_WARP`.

    With ``data_dir``, the colour Oxford images graf img1 and bikes img1 are added (names
    ``oxford-graf``, ``oxford-bikes``) where present: unlike scikit-image's photos, which
    ``visioncell train-pca`` uses for the colour PCA bases, they are held out of training.
    """
    sources = [(name, skimage_photo(name)) for name in photos]
    if data_dir is not None:
        for seq in ("graf", "bikes"):
            path = Path(data_dir) / "registration" / "oxford" / seq / "img1.png"
            if path.is_file():
                sources.append((f"oxford-{seq}", _read_rgb(path)))
    pairs = []
    for name, a in sources:
        H = similarity_about_centre(a.shape[:2], *MILD_WARP)
        warped = _warp(a, H, (a.shape[1], a.shape[0]))
        for model, params in ILLUMINATION_MODELS.items():
            b = apply_illumination(warped, model, params)
            note = f"{model} {params}, then rotation {MILD_WARP[0]} deg, scale {MILD_WARP[1]}"
            pairs.append(ImagePair("illumination", f"{name}/{model}", a, b, H, 0.0, None, note))
    return pairs


def scale_pairs(
    image: np.ndarray, factors: tuple[float, ...] = (1.25, 1.5, 2.0, 2.5, 3.0, 4.0)
) -> list[ImagePair]:
    """The image against itself shrunk by each factor ``s`` (chapter eq. 14: ``b`` shows the
    scene ``1/s`` as high), with 2 deg rotation so that ``s = 1`` is not a pixel copy.

    The homography maps pixel centres: ``x_b = R (x_a + 0.5) / s - 0.5``.
    """
    h, w = image.shape[:2]
    pairs = []
    for s in factors:
        if s < 1.0:
            raise ValueError(f"scale factors must be >= 1, got {s!r}")
        size = (max(16, round(w / s)), max(16, round(h / s)))
        S = np.array([[1 / s, 0, 0.5 / s - 0.5], [0, 1 / s, 0.5 / s - 0.5], [0, 0, 1.0]])
        R = similarity_about_centre((size[1], size[0]), 2.0, 1.0)
        H = R @ S
        b = cv2.warpPerspective(
            cv2.resize(image, size, interpolation=cv2.INTER_AREA), R, size, flags=cv2.INTER_LINEAR
        )
        pairs.append(ImagePair("scale", f"x{s:g}", image, b, H, float(s), None, "synthetic"))
    return pairs


# -- simulated wheel views -------------------------------------------------------------------
def _plane_map(K: np.ndarray, T_cam_obj: np.ndarray, z_m: float) -> np.ndarray:
    """3x3 map from plane coordinates ``(x, y)`` at height ``z_m`` of the object to pixels."""
    R, t = T_cam_obj[:3, :3], T_cam_obj[:3, 3]
    return K @ np.column_stack([R[:, 0], R[:, 1], z_m * R[:, 2] + t])


def sim_wheel_pairs(
    wheel: str = "wheel-5spoke",
    views: tuple[tuple[str, float, float, float], ...] = (
        ("rotated", 30.0, 0.0, 0.42),
        ("translated", 0.0, 0.06, 0.42),
        ("scaled", 0.0, 0.0, 0.55),
    ),
) -> list[ImagePair]:
    """Top views of a car wheel on the belt, as in chapter Figure 15 (rotated, translated,
    scaled), rendered by the simulator with an ideal lens, no noise and no motion blur.

    ``views`` holds ``(name, yaw_deg, shift_m, distance_m)`` of view ``b``; view ``a`` is the
    wheel at the station with yaw 0 seen from 0.42 m. ``yaw`` turns the wheel about its axis,
    ``shift`` moves it along the belt, ``distance`` raises the camera (scale change).

    Ground truth: the homography induced by the wheel's top plane (its highest point,
    ``z = bounds[1, 2]`` in the object frame), ``H = G_b G_a^-1`` with ``G = K [r1 r2 z r3 + t]``
    from the true ``T_cam_obj`` of each view. It is exact on that plane; wheel points below it
    (the recessed rim face, the tyre shoulders) are off by their parallax, reported in ``note``
    as the largest shift over the wheel's disc of a point 3 cm lower. ``mask_a`` is the disc of
    0.9 times the wheel's radius in ``a`` (the belt is another plane and does not follow ``H``).
    """
    os.environ.setdefault("MUJOCO_GL", "egl")
    from robot.sim import CATALOGUE, CameraSpec, SimConfig, SimEngine
    from robot.sim.imaging import capture
    from robot.sim.poses import viewpoint

    spec = CameraSpec(dist=(0.0,) * 5, noise_std_dn=0.0, motion_blur=False)
    engine = SimEngine(SimConfig(camera=spec))
    conveyor = engine.config.layout.conveyor
    top_z = float(CATALOGUE[wheel].geometry().bounds[1, 2])
    radius = float(np.abs(CATALOGUE[wheel].geometry().bounds[:, :2]).max())
    station = conveyor.station_point + np.array([0.0, 0.0, top_z])

    def shot(yaw_deg: float, shift_m: float, distance_m: float):
        engine.clear_objects()
        obj = engine.spawn(wheel, s_m=conveyor.station_s_m + shift_m, yaw_rad=math.radians(yaw_deg))
        q = viewpoint(station, "top", distance_m=distance_m)
        img = capture(engine, q).rgb
        T_cam_obj = np.linalg.inv(spec.T_base_cam(q)) @ obj.T_base_obj
        return img, T_cam_obj

    try:
        a, T_a = shot(0.0, 0.0, 0.42)
        G_a = _plane_map(spec.K, T_a, top_z)
        # The mask is the disc of 0.9 R on the top plane: the tyre's rounded shoulder leaves
        # the belt visible just inside the full radius, and the belt does not follow H.
        t = np.linspace(0, 2 * np.pi, 90)
        circle = np.c_[radius * np.cos(t), radius * np.sin(t), np.ones(90)]
        inner = np.c_[0.9 * circle[:, :2], np.ones(90)]
        px = inner @ G_a.T
        mask = np.zeros(a.shape[:2], np.uint8)
        cv2.fillPoly(mask, [np.rint(px[:, :2] / px[:, 2:]).astype(np.int32)], 1)
        pairs = []
        for name, yaw, shift, dist in views:
            b, T_b = shot(yaw, shift, dist)
            H = _plane_map(spec.K, T_b, top_z) @ np.linalg.inv(G_a)
            H = H / H[2, 2]
            # Parallax of a point 3 cm below the top plane, over the disc.
            low_a = circle @ _plane_map(spec.K, T_a, top_z - 0.03).T
            low_b = circle @ _plane_map(spec.K, T_b, top_z - 0.03).T
            pred = (low_a @ H.T)[:, :2] / (low_a @ H.T)[:, 2:]
            err = float(np.abs(pred - low_b[:, :2] / low_b[:, 2:]).max())
            note = (
                f"{wheel} {name}: yaw {yaw:g} deg, shift {shift:g} m, camera {dist:g} m; "
                f"top-plane homography, parallax 3 cm below it <= {err:.1f} px"
            )
            pairs.append(ImagePair("sim-wheel", name, a, b, H, yaw, mask.astype(bool), note))
        return pairs
    finally:
        engine.stop()


# -- real illumination changes seen by a fixed camera ------------------------------------------
#: The real illumination sets and what the methods receive (``data/illumination``, see its
#: README): MIMO as 8-bit sRGB and as 16-bit linear camera RGB (Beigpour et al., IEEE TIP
#: 23(1), 2014), SFU as dark 8-bit linear RGB (Barnard et al., Color Res. Appl. 27(3), 2002).
REAL_ILLUMINATION_SETS = ("mimo-srgb8", "mimo-linear16", "sfu-linear8")
#: Reference lamp combination of every MIMO scene (``<lamp1>_<lamp2>``, b/r/w = blue, red,
#: white): the one combination that every scene has and that did not move.
MIMO_REFERENCE = "b_r"
#: White level of the 16-bit MIMO files, fixed for the whole set so that the pairs keep their
#: real exposure differences: the brightest value in the 58 files is 9918 (the 8-bit sRGB files
#: are instead each scaled to their own brightest pixel, measured here).
MIMO_WHITE_LEVEL = 10000.0
#: SFU reference lamp (4100 K) and the two lamps compared with it.
SFU_REFERENCE = "solux-4100"
SFU_LAMPS = ("syl-50MR16Q", "solux-4700+3202")
#: Images left out, with the reason (measured by phase correlation of log-gradient images
#: against the reference; the overlap-error test tolerates the 0.4-1.2 px shifts of the rest).
REAL_LEFT_OUT: dict[str, str] = {
    "mimo/pmug_w_b": "camera moved: 6.8 px against pmug_b_r (data README: about 4 px)",
    "mimo/pmug_w_r": "camera moved: 6.7 px against pmug_b_r (data README: about 4 px)",
    "sfu/ball": "camera moved: 3.2 px between the lamps (data README: ball 3 px)",
}


def _read_any(path: Path) -> np.ndarray:
    """RGB image at ``path`` with its stored bit depth (uint8 or uint16), read-only."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.ndim != 3 or img.shape[2] < 3:
        raise FileNotFoundError(f"cannot read an RGB image from {path}")
    img = np.ascontiguousarray(img[..., 2::-1])
    img.setflags(write=False)
    return img


@functools.cache
def _read_real(path: Path) -> np.ndarray:
    return _read_any(path)


def _mean_ratio(a: np.ndarray, b: np.ndarray) -> float:
    return float(b.astype(np.float64).mean() / max(a.astype(np.float64).mean(), 1e-9))


def mimo_pairs(data_dir: Path, variant: str = "srgb8") -> list[ImagePair]:
    """Every lamp combination of each MIMO scene against :data:`MIMO_REFERENCE`.

    Parameters
    ----------
    data_dir : Path
        The shared data directory (``data_dir/illumination/mimo`` is read).
    variant : {"srgb8", "linear16"}
        ``srgb8``: the 8-bit sRGB files (each scaled to its brightest pixel); ``linear16``:
        the 16-bit linear camera RGB (uint16 images; white level :data:`MIMO_WHITE_LEVEL`).

    Returns
    -------
    list of ImagePair
        Sequence ``mimo-<variant>``, name ``<scene>/<combination>``, identity ``H``, ``param``
        = mean brightness of ``b`` over ``a`` (linear values); the images in
        :data:`REAL_LEFT_OUT` are left out.

    Raises
    ------
    FileNotFoundError
        The folder is absent.
    ValueError
        Unknown variant.
    """
    if variant not in ("srgb8", "linear16"):
        raise ValueError(f"variant must be 'srgb8' or 'linear16', got {variant!r}")
    folder = Path(data_dir) / "illumination" / "mimo"
    files = sorted((folder / variant).glob("*.png"))
    if not files or not (folder / "linear16").is_dir():
        raise FileNotFoundError(f"{folder / variant} is absent (see ../shared/data/README.md)")
    scenes = sorted({f.stem.split("_")[0] for f in files})
    pairs = []
    for scene in scenes:
        ref = folder / variant / f"{scene}_{MIMO_REFERENCE}.png"
        if not ref.is_file():
            continue
        a = _read_real(ref)
        a_lin = _read_real(folder / "linear16" / ref.name)
        for f in files:
            combo = f.stem.removeprefix(scene + "_")
            if not f.stem.startswith(scene + "_") or combo == MIMO_REFERENCE:
                continue
            if f"mimo/{f.stem}" in REAL_LEFT_OUT:
                continue
            b = _read_real(f)
            ratio = _mean_ratio(a_lin, _read_real(folder / "linear16" / f.name))
            note = f"MIMO {scene}: lamps {combo} against {MIMO_REFERENCE}, {variant}"
            pairs.append(
                ImagePair(f"mimo-{variant}", f"{scene}/{combo}", a, b, np.eye(3), ratio, None, note)
            )
    return pairs


def sfu_pairs(data_dir: Path) -> list[ImagePair]:
    """Each SFU scene under :data:`SFU_LAMPS` against :data:`SFU_REFERENCE` (8-bit linear).

    Returns pairs of sequence ``sfu-linear8``, name ``<scene>/<lamp>``, identity ``H``,
    ``param`` = mean brightness of ``b`` over ``a``; scenes in :data:`REAL_LEFT_OUT` are left
    out. Raises ``FileNotFoundError`` when the folder is absent.
    """
    folder = Path(data_dir) / "illumination" / "sfu"
    refs = sorted(folder.glob(f"*_{SFU_REFERENCE}.tif"))
    if not refs:
        raise FileNotFoundError(f"{folder} is absent (see ../shared/data/README.md)")
    pairs = []
    for ref in refs:
        scene = ref.name.removesuffix(f"_{SFU_REFERENCE}.tif")
        if f"sfu/{scene}" in REAL_LEFT_OUT:
            continue
        a = _read_real(ref)
        for lamp in SFU_LAMPS:
            path = folder / f"{scene}_{lamp}.tif"
            if not path.is_file():
                continue
            b = _read_real(path)
            note = f"SFU {scene}: {lamp} against {SFU_REFERENCE}, 8-bit linear"
            pairs.append(
                ImagePair(
                    "sfu-linear8", f"{scene}/{lamp}", a, b, np.eye(3), _mean_ratio(a, b), None, note
                )
            )
    return pairs


def real_illumination_pairs(data_dir: Path, sets: tuple[str, ...] = REAL_ILLUMINATION_SETS):
    """The pairs of the named real illumination sets, and for each absent set the reason.

    Returns
    -------
    pairs : list of ImagePair
    skipped : dict
        Set name -> why it is absent.
    """
    bad = [s for s in sets if s not in REAL_ILLUMINATION_SETS]
    if bad:
        raise ValueError(f"sets must be among {REAL_ILLUMINATION_SETS}, got {bad}")
    pairs: list[ImagePair] = []
    skipped: dict[str, str] = {}
    for s in sets:
        try:
            if s == "sfu-linear8":
                pairs += sfu_pairs(data_dir)
            else:
                pairs += mimo_pairs(data_dir, s.removeprefix("mimo-"))
        except FileNotFoundError as exc:
            skipped[s] = str(exc)
    return pairs, skipped
