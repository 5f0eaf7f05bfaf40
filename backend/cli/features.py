"""``visioncell train-pca``: train the PCA bases of PCA-SIFT, GLOH and the colour-invariant
descriptors (chapter section 3.4.2, equations 18-19) from public images.

The backend gathers the training images -- scikit-image's bundled colour photos, the Oxford
images in the data directory (minus the sequences the registration benchmark evaluates on)
and frames of the simulated cell -- and :func:`vision.features.pca_training.train_basis`
fits and records each basis.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import typer
from rich.console import Console

from vision.errors import CameraError
from vision.sources import read_rgb

__all__ = ["SKIMAGE_PHOTOS", "oxford_images", "sim_frames", "skimage_images", "train_pca"]

err = Console(stderr=True, soft_wrap=True)

#: scikit-image's bundled colour photographs used for training (no download needed).
SKIMAGE_PHOTOS = (
    "astronaut",
    "chelsea",
    "coffee",
    "rocket",
    "hubble_deep_field",
    "immunohistochemistry",
    "retina",
    "stereo_motorcycle",
)
#: Oxford sequences the registration benchmark evaluates on: excluded from training.
EVAL_SEQUENCES = ("graf", "boat", "bikes")


def skimage_images(names: tuple[str, ...] = SKIMAGE_PHOTOS) -> list[tuple[str, np.ndarray]]:
    """scikit-image's colour photos as ``(name, rgb uint8)``; large ones halved to <= 1000 px."""
    try:
        import skimage.data
    except ImportError as exc:  # scikit-image is in the dev/bench extras only
        raise RuntimeError(
            "scikit-image is needed for its bundled photos: pip install 'visioncell[dev]' "
            "(or pass --no-skimage)"
        ) from exc
    out = []
    for name in names:
        img = getattr(skimage.data, name)()
        if isinstance(img, tuple):  # stereo pairs: the left view
            img = img[0]
        img = np.asarray(img)[..., :3]
        while max(img.shape[:2]) > 1000:
            img = cv2.pyrDown(img)
        out.append((f"skimage:{name}", np.ascontiguousarray(img, dtype=np.uint8)))
    return out


def oxford_images(data_dir: Path, exclude: tuple[str, ...]) -> list[tuple[str, np.ndarray]]:
    """``<data_dir>/registration/oxford/<seq>/img*.png`` as RGB, skipping ``exclude``."""
    root = data_dir / "registration" / "oxford"
    out = []
    for path in sorted(root.glob("*/img*.png")):
        if path.parent.name in exclude:
            continue
        try:
            out.append((f"oxford:{path.parent.name}/{path.name}", read_rgb(path)))
        except CameraError:  # unreadable files are skipped
            continue
    return out


def sim_frames(n: int) -> list[tuple[str, np.ndarray]]:
    """``n`` frames of the simulated demo cell (MuJoCo, needs ``MUJOCO_GL=egl`` headless):
    the eye-in-hand camera at the standard viewpoints, the demo objects rotated along the
    belt between rounds so different objects sit under the camera. Deterministic: the
    engine's object yaws and the sensor noise are seeded, and each frame is taken at rest."""
    from backend.hardware import headless_mujoco

    headless_mujoco()
    from robot.sim import DEMO_OBJECTS, SimEngine, populate_demo
    from robot.sim.imaging import capture
    from robot.sim.poses import standard_configurations

    engine = SimEngine()
    views = ["top", "inner", "outer", "upstream", "table"]
    configs = standard_configurations()
    frames = []
    for i in range(n):
        rnd, view = divmod(i, len(views))
        if view == 0:
            engine.clear_objects()
            k = rnd % len(DEMO_OBJECTS)
            populate_demo(engine, names=DEMO_OBJECTS[k:] + DEMO_OBJECTS[:k])
        image = capture(engine, configs[views[view]])
        frames.append((f"sim:{views[view]}-{rnd}", np.asarray(image.rgb)))
    return frames


def train_pca(
    out_dir: Annotated[
        Path | None,
        typer.Option("--out", help="Output folder (default: the package's data folder)"),
    ] = None,
    kinds: Annotated[
        list[str] | None,
        typer.Option("--kind", help="Basis to train (repeatable; default: all available)"),
    ] = None,
    patches: Annotated[
        int, typer.Option("--patches", min=2, help="Descriptors per basis (chapter: ~20,000)")
    ] = 20000,
    sim: Annotated[
        int, typer.Option("--sim-frames", min=0, help="Simulated cell frames (0: none)")
    ] = 20,
    photos: Annotated[
        list[str] | None,
        typer.Option("--photo", help="scikit-image photo to use (repeatable; default: all)"),
    ] = None,
    use_skimage: Annotated[
        bool, typer.Option("--skimage/--no-skimage", help="Use scikit-image's colour photos")
    ] = True,
    oxford: Annotated[
        bool, typer.Option("--oxford/--no-oxford", help="Use the Oxford images")
    ] = True,
    include_eval: Annotated[
        bool,
        typer.Option(
            "--include-eval-sequences",
            help=f"Also train on the benchmark's Oxford sequences ({', '.join(EVAL_SEQUENCES)}): "
            "train-on-test, for experiments only",
        ),
    ] = False,
    data_dir: Annotated[
        Path | None, typer.Option("--data-dir", help="Data folder (default: settings)")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Sampling seed")] = 0,
    max_features: Annotated[
        int, typer.Option("--max-features", min=1, help="Strongest keypoints per image")
    ] = 3000,
    float32: Annotated[
        bool, typer.Option("--float32", help="Store components as float32 (default float16)")
    ] = False,
) -> None:
    """Train the PCA bases (pca-sift, gloh, color-sift, color-surf) on ~20,000 descriptors
    from public images and write versioned .npz files with their provenance."""
    from vision.features.pca import BASIS_KINDS, DATA_DIR, save_npz
    from vision.features.pca_training import train_basis, unavailable_reason

    wanted = list(kinds or BASIS_KINDS)
    for kind in wanted:
        if kind not in BASIS_KINDS:
            err.print(f"[red]error:[/red] --kind {kind!r}: choose one of {', '.join(BASIS_KINDS)}")
            raise typer.Exit(2)
    todo = []
    for kind in wanted:
        why = unavailable_reason(kind)
        if why:
            err.print(f"[yellow]skipping {kind}:[/yellow] {why}")
        else:
            todo.append(kind)
    if not todo:
        err.print("[red]error:[/red] no basis can be trained here")
        raise typer.Exit(1)

    if data_dir is None:
        from backend.cli import load_settings

        data_dir = load_settings().data_dir
    images: list[tuple[str, np.ndarray]] = []
    sources: dict[str, object] = {}
    if use_skimage:
        chosen = tuple(photos) if photos else SKIMAGE_PHOTOS
        bad = [p for p in chosen if p not in SKIMAGE_PHOTOS]
        if bad:
            err.print(
                f"[red]error:[/red] --photo {bad[0]!r}: choose from {', '.join(SKIMAGE_PHOTOS)}"
            )
            raise typer.Exit(2)
        try:
            images += skimage_images(chosen)
        except RuntimeError as exc:
            err.print(f"[red]error:[/red] {exc}")
            raise typer.Exit(1) from None
        sources["skimage"] = list(chosen)
    if oxford:
        exclude = () if include_eval else EVAL_SEQUENCES
        ox = oxford_images(Path(data_dir), exclude)
        images += ox
        sources["oxford"] = {
            "root": str(Path(data_dir) / "registration" / "oxford"),
            "excluded_sequences": list(exclude),
            "images": len(ox),
        }
        err.print(
            f"oxford: {len(ox)} images"
            + (f" (excluded evaluation sequences {', '.join(exclude)})" if exclude else "")
        )
    if sim:
        err.print(f"rendering {sim} simulated frames ...")
        try:
            frames = sim_frames(sim)
        except Exception as exc:  # no GL context, MuJoCo missing: train without them
            err.print(f"[yellow]no simulated frames:[/yellow] {exc}")
            frames = []
        images += frames
        sources["sim"] = {"frames": len(frames)}
    if not images:
        err.print("[red]error:[/red] no training images (all sources disabled or empty)")
        raise typer.Exit(1)
    err.print(f"{len(images)} training images")

    out = Path(out_dir) if out_dir is not None else DATA_DIR
    for kind in todo:

        def tick(name: str, done: int, total: int, kind: str = kind) -> None:
            err.print(f"  {kind}: [{done}/{total}] {name}")

        err.print(f"[bold]{kind}[/bold]: sampling {patches} descriptors")
        basis = train_basis(
            kind,
            images,
            n_patches=patches,
            seed=seed,
            max_features=max_features,
            provenance={"source_sets": sources},
            progress=tick,
        )
        path = save_npz(basis, out / f"{kind}.npz", float16=not float32)
        from vision.features.pca import load_npz

        saved = load_npz(path)
        typer.echo(
            f"{kind}: {basis.provenance['patches']} patches, {basis.dim_in} -> {basis.dim_out} "
            f"dims, explained variance {basis.explained_variance:.3f}, version {saved.version}, "
            f"{path} ({path.stat().st_size / 1024:.0f} KiB)"
        )
