"""Compiled inner loops of the active contour (Numba).

The snake's iterations touch a few hundred points each; in NumPy every iteration would
cost some ten array calls of a few microseconds each, so the whole evolution, resampling
and loop removal included, runs here in one compiled call.  The maths is documented in
:mod:`vision.segmentation.snake` (eqs. 6-11) and :mod:`vision.segmentation.contours`; these
functions are its direct transcription.  ``cache=True`` keeps the machine code on disk, so
only the first run on a machine pays the compilation (a few seconds).
"""

from __future__ import annotations

import numba as nb
import numpy as np

# ---------------------------------------------------------------------------------------
# Geometry of closed polylines
# ---------------------------------------------------------------------------------------


@nb.njit(cache=True)
def signed_area(c):
    """Shoelace area; positive for clockwise-on-screen (y down) contours."""
    n = c.shape[0]
    s = 0.0
    for i in range(n):
        j = (i + 1) % n
        s += c[i, 0] * c[j, 1] - c[j, 0] * c[i, 1]
    return 0.5 * s


@nb.njit(cache=True)
def resample(c, n_out):
    """``n_out`` points equally spaced by arc length along the closed polyline ``c``."""
    n = c.shape[0]
    cum = np.empty(n + 1)
    cum[0] = 0.0
    for i in range(n):
        j = (i + 1) % n
        cum[i + 1] = cum[i] + np.hypot(c[j, 0] - c[i, 0], c[j, 1] - c[i, 1])
    total = cum[n]
    out = np.empty((n_out, 2))
    if total <= 0.0:
        for k in range(n_out):
            out[k, 0] = c[0, 0]
            out[k, 1] = c[0, 1]
        return out
    seg = 0
    for k in range(n_out):
        t = total * k / n_out
        while seg < n - 1 and cum[seg + 1] <= t:
            seg += 1
        length = cum[seg + 1] - cum[seg]
        f = 0.0 if length <= 0.0 else (t - cum[seg]) / length
        j = (seg + 1) % n
        out[k, 0] = c[seg, 0] + f * (c[j, 0] - c[seg, 0])
        out[k, 1] = c[seg, 1] + f * (c[j, 1] - c[seg, 1])
    return out


@nb.njit(cache=True)
def first_crossing(c):
    """First pair of crossing non-adjacent edges ``(i, j)``, ``i < j``, and the crossing point.

    Returns ``(-1, -1, 0.0, 0.0)`` when the polyline is simple.
    """
    n = c.shape[0]
    for i in range(n - 2):
        i2 = i + 1
        ax, ay, bx, by = c[i, 0], c[i, 1], c[i2, 0], c[i2, 1]
        dix, diy = bx - ax, by - ay
        lox, hix = min(ax, bx), max(ax, bx)
        loy, hiy = min(ay, by), max(ay, by)
        jmax = n if i > 0 else n - 1  # edge n-1 closes onto point 0: adjacent to edge 0
        for j in range(i + 2, jmax):
            j2 = (j + 1) % n
            cx, cy, dx, dy = c[j, 0], c[j, 1], c[j2, 0], c[j2, 1]
            if max(cx, dx) < lox or min(cx, dx) > hix or max(cy, dy) < loy or min(cy, dy) > hiy:
                continue
            djx, djy = dx - cx, dy - cy
            den = dix * djy - diy * djx
            if den == 0.0:
                continue
            rx, ry = cx - ax, cy - ay
            s = (rx * djy - ry * djx) / den
            t = (rx * diy - ry * dix) / den
            if 0.0 < s < 1.0 and 0.0 < t < 1.0:
                return i, j, ax + s * dix, ay + s * diy
    return -1, -1, 0.0, 0.0


@nb.njit(cache=True)
def remove_loops(c, max_loops):
    """Cut self-intersection loops, keeping the part with the larger area each time."""
    for _ in range(max_loops):
        n = c.shape[0]
        if n < 4:
            break
        i, j, px, py = first_crossing(c)
        if i < 0:
            break
        inner = np.empty((j - i + 1, 2))
        inner[0, 0], inner[0, 1] = px, py
        inner[1:] = c[i + 1 : j + 1]
        outer = np.empty((n - (j - i) + 1, 2))
        outer[: i + 1] = c[: i + 1]
        outer[i + 1, 0], outer[i + 1, 1] = px, py
        outer[i + 2 :] = c[j + 1 :]
        c = inner if abs(signed_area(inner)) > abs(signed_area(outer)) else outer
    return c


# ---------------------------------------------------------------------------------------
# Image sampling and the cyclic pentadiagonal solve
# ---------------------------------------------------------------------------------------


@nb.njit(cache=True)
def bilinear(field, x, y, ch):
    """Bilinear sample of channel ``ch`` of a (H, W, C) field; points clamped to the centres."""
    h, w = field.shape[0], field.shape[1]
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    x0 = min(int(x), w - 2)
    y0 = min(int(y), h - 2)
    fx, fy = x - x0, y - y0
    top = field[y0, x0, ch] * (1.0 - fx) + field[y0, x0 + 1, ch] * fx
    bot = field[y0 + 1, x0, ch] * (1.0 - fx) + field[y0 + 1, x0 + 1, ch] * fx
    return top * (1.0 - fy) + bot * fy


@nb.njit(cache=True)
def solve_cyclic(lband, border, y_mat, s_inv, r, out):
    """Solve ``(A + gamma I) out = r`` for one column with the precomputed factors.

    ``A + gamma I = [[B, C], [C^T, D]]`` with ``B`` the pentadiagonal leading block of size
    n-2 (banded Cholesky ``lband``: rows = diagonal, first and second sub-diagonals, the
    layout of ``scipy.linalg.cholesky_banded(lower=True)``), ``C = border``, ``Y = B^-1 C`` and
    ``S^-1 = (D - C^T Y)^-1`` (Schur complement): ``z = B^-1 r1``, ``x2 = S^-1 (r2 - C^T z)``,
    ``x1 = z - Y x2``.  O(n) per solve.
    """
    m = lband.shape[1]
    z = np.empty(m)
    # Forward: L z' = r1.
    for i in range(m):
        v = r[i]
        if i >= 1:
            v -= lband[1, i - 1] * z[i - 1]
        if i >= 2:
            v -= lband[2, i - 2] * z[i - 2]
        z[i] = v / lband[0, i]
    # Backward: L^T z = z'.
    for i in range(m - 1, -1, -1):
        v = z[i]
        if i + 1 < m:
            v -= lband[1, i] * z[i + 1]
        if i + 2 < m:
            v -= lband[2, i] * z[i + 2]
        z[i] = v / lband[0, i]
    t0 = r[m]
    t1 = r[m + 1]
    for i in range(m):
        t0 -= border[i, 0] * z[i]
        t1 -= border[i, 1] * z[i]
    x0 = s_inv[0, 0] * t0 + s_inv[0, 1] * t1
    x1 = s_inv[1, 0] * t0 + s_inv[1, 1] * t1
    for i in range(m):
        out[i] = z[i] - y_mat[i, 0] * x0 - y_mat[i, 1] * x1
    out[m] = x0
    out[m + 1] = x1


# ---------------------------------------------------------------------------------------
# The snake
# ---------------------------------------------------------------------------------------


@nb.njit(cache=True)
def snake_energy(x, energy, alpha, beta):
    """Eq. 8: ``E_int`` (eq. 9, index differences) plus ``sum E_img`` (eqs. 10-11)."""
    n = x.shape[0]
    e = 0.0
    for i in range(n):
        ip, im = (i + 1) % n, (i - 1) % n
        d1x, d1y = x[ip, 0] - x[i, 0], x[ip, 1] - x[i, 1]
        d2x = x[ip, 0] - 2.0 * x[i, 0] + x[im, 0]
        d2y = x[ip, 1] - 2.0 * x[i, 1] + x[im, 1]
        e += alpha * (d1x * d1x + d1y * d1y) + beta * (d2x * d2x + d2y * d2y)
        e += bilinear(energy, x[i, 0], x[i, 1], 0)
    return e


@nb.njit(cache=True)
def run_snake(
    field,
    energy,
    x,
    lband,
    border,
    y_mat,
    s_inv,
    alpha,
    beta,
    gamma,
    balloon,
    max_step_px,
    resample_every,
    max_num_iter,
    max_px_move,
    snap_its,
    snaps,
    energies,
    energy_its,
):
    """Semi-implicit snake iterations (Kass et al. 1988) with resampling and convergence test.

    ``field`` holds (f_x, f_y, stop) per pixel; ``energy`` is E_img (H, W, 1).  Writes the
    requested snapshots into ``snaps`` and eq. 8 at each check into ``energies`` /
    ``energy_its``.  Returns ``(x, iterations, converged, n_energy_records)``.
    """
    n = x.shape[0]
    h, w = field.shape[0], field.shape[1]
    xmax, ymax = w - 1.0, h - 1.0
    x = x.copy()
    prev = x.copy()
    rhs_x = np.empty(n)
    rhs_y = np.empty(n)
    new_x = np.empty(n)
    new_y = np.empty(n)
    n_rec = 0
    energies[n_rec] = snake_energy(x, energy, alpha, beta)
    energy_its[n_rec] = 0
    n_rec += 1
    k_snap = 0
    while k_snap < snap_its.shape[0] and snap_its[k_snap] == 0:
        snaps[k_snap] = x
        k_snap += 1
    sign = 1.0 if signed_area(x) >= 0.0 else -1.0
    last_check = 0
    converged = False
    it = 0
    for it in range(1, max_num_iter + 1):
        for i in range(n):
            px, py = x[i, 0], x[i, 1]
            fx = bilinear(field, px, py, 0)
            fy = bilinear(field, px, py, 1)
            if balloon != 0.0:
                # Outward unit normal (t_y, -t_x) of a clockwise contour, t the central tangent.
                ip, im = (i + 1) % n, (i - 1) % n
                tx, ty = x[ip, 0] - x[im, 0], x[ip, 1] - x[im, 1]
                k = balloon * sign * bilinear(field, px, py, 2) / max(np.hypot(tx, ty), 1e-12)
                fx += k * ty
                fy -= k * tx
            rhs_x[i] = gamma * px + fx
            rhs_y[i] = gamma * py + fy
        solve_cyclic(lband, border, y_mat, s_inv, rhs_x, new_x)
        solve_cyclic(lband, border, y_mat, s_inv, rhs_y, new_y)
        for i in range(n):
            sx, sy = new_x[i] - x[i, 0], new_y[i] - x[i, 1]
            length = np.hypot(sx, sy)
            if length > max_step_px:
                sx *= max_step_px / length
                sy *= max_step_px / length
            x[i, 0] = min(max(x[i, 0] + sx, 0.0), xmax)
            x[i, 1] = min(max(x[i, 1] + sy, 0.0), ymax)
        while k_snap < snap_its.shape[0] and snap_its[k_snap] == it:
            snaps[k_snap] = x
            k_snap += 1
        if it % resample_every == 0 or it == max_num_iter:
            moved = 0.0
            for i in range(n):
                moved += np.hypot(x[i, 0] - prev[i, 0], x[i, 1] - prev[i, 1])
            moved /= n * (it - last_check)
            last_check = it
            x = resample(remove_loops(x, 50), n)
            sign = 1.0 if signed_area(x) >= 0.0 else -1.0
            prev[:, :] = x
            energies[n_rec] = snake_energy(x, energy, alpha, beta)
            energy_its[n_rec] = it
            n_rec += 1
            if moved < max_px_move:
                converged = True
                break
    return x, it, converged, n_rec
