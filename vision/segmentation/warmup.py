"""Load (or, on a fresh machine, compile) the segmentation's Numba kernels ahead of time."""

from __future__ import annotations

import time

import numpy as np

__all__ = ["warm_up"]


def warm_up() -> float:
    """Run the snake and both level-set solvers once on a tiny image; return the seconds spent.

    The compiled kernels are cached on disk (``__pycache__`` beside the sources, or Numba's
    user cache when that is read-only).  The first call on a machine compiles them (some ten
    to thirty seconds); later processes only load them (well under a second).  A server calls
    this at start-up so that the first real request does not pay it.
    """
    from vision.segmentation.contours import circle_contour
    from vision.segmentation.levelset import chan_vese
    from vision.segmentation.snake import active_contour

    t0 = time.perf_counter()
    yy, xx = np.mgrid[:48, :48]
    img = (((xx - 24) ** 2 + (yy - 24) ** 2 < 12**2) * 0.6 + 0.2).astype(np.float32)
    init = circle_contour((24.0, 24.0), 18.0, 40)
    active_contour(img, init, balloon=-0.6, max_num_iter=20)
    chan_vese(img, init, max_num_iter=5)
    chan_vese(img, init, method="pde", max_num_iter=5)
    return time.perf_counter() - t0
