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
    """A pair of crossing non-adjacent edges ``(i, j)``, ``i < j``, and the crossing point.

    Sweep along x: edges sorted by their left end, each one compared only with the edges
    whose x-range starts before its own ends (then a y-range test, then the exact test), so
    a simple contour costs O(n log n).  Returns ``(-1, -1, 0.0, 0.0)`` when the polyline is
    simple.
    """
    n = c.shape[0]
    x0 = np.empty(n)
    x1 = np.empty(n)
    for e in range(n):
        f = (e + 1) % n
        x0[e] = min(c[e, 0], c[f, 0])
        x1[e] = max(c[e, 0], c[f, 0])
    order = np.argsort(x0)
    for a in range(n):
        i = order[a]
        i2 = (i + 1) % n
        ax, ay, bx, by = c[i, 0], c[i, 1], c[i2, 0], c[i2, 1]
        loy, hiy = min(ay, by), max(ay, by)
        for b in range(a + 1, n):
            j = order[b]
            if x0[j] > x1[i]:
                break
            d = abs(i - j)
            if d <= 1 or d == n - 1:  # the same or adjacent edges share a point
                continue
            j2 = (j + 1) % n
            cx, cy, dx, dy = c[j, 0], c[j, 1], c[j2, 0], c[j2, 1]
            if max(cy, dy) < loy or min(cy, dy) > hiy:
                continue
            dix, diy = bx - ax, by - ay
            djx, djy = dx - cx, dy - cy
            den = dix * djy - diy * djx
            if den == 0.0:
                continue
            rx, ry = cx - ax, cy - ay
            s = (rx * djy - ry * djx) / den
            t = (rx * diy - ry * dix) / den
            if 0.0 < s < 1.0 and 0.0 < t < 1.0:
                px, py = ax + s * dix, ay + s * diy
                return min(i, j), max(i, j), px, py
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
def bilinear3(field, x, y):
    """The three channels of a (H, W, 3) field at one point (one set of weights)."""
    h, w = field.shape[0], field.shape[1]
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    x0 = min(int(x), w - 2)
    y0 = min(int(y), h - 2)
    fx, fy = x - x0, y - y0
    w00, w01 = (1.0 - fx) * (1.0 - fy), fx * (1.0 - fy)
    w10, w11 = (1.0 - fx) * fy, fx * fy
    a = (
        w00 * field[y0, x0, 0]
        + w01 * field[y0, x0 + 1, 0]
        + w10 * field[y0 + 1, x0, 0]
        + w11 * field[y0 + 1, x0 + 1, 0]
    )
    b = (
        w00 * field[y0, x0, 1]
        + w01 * field[y0, x0 + 1, 1]
        + w10 * field[y0 + 1, x0, 1]
        + w11 * field[y0 + 1, x0 + 1, 1]
    )
    c = (
        w00 * field[y0, x0, 2]
        + w01 * field[y0, x0 + 1, 2]
        + w10 * field[y0 + 1, x0, 2]
        + w11 * field[y0 + 1, x0 + 1, 2]
    )
    return a, b, c


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
            fx, fy, stop = bilinear3(field, px, py)
            if balloon != 0.0:
                # Outward unit normal (t_y, -t_x) of a clockwise contour, t the central tangent.
                ip, im = (i + 1) % n, (i - 1) % n
                tx, ty = x[ip, 0] - x[im, 0], x[ip, 1] - x[im, 1]
                k = balloon * sign * stop / max(np.hypot(tx, ty), 1e-12)
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


# ---------------------------------------------------------------------------------------
# Chan-Vese level-set PDE: one semi-implicit Gauss-Seidel sweep
# ---------------------------------------------------------------------------------------


@nb.njit(cache=True)
def chan_vese_sweep(phi, diff, mu, dt, band, max_change):
    """One sweep of Chan and Vese's (2001) semi-implicit scheme, in place; returns max |change|.

    For each pixel (row-major order, so the up and left neighbours are already new: a
    Gauss-Seidel sweep) the curvature term ``div(grad phi / |grad phi|)`` is discretised with the
    coefficients ``C1..C4`` of their eq. 9 (inverse gradient magnitudes on the four half-pixel
    faces), taken implicitly in the centre value:

        phi <- (phi + dt delta(phi) (mu sum_k C_k phi_k - diff)) / (1 + dt delta(phi) mu sum_k C_k)

    with ``delta`` the regularised Dirac (eps = 1) and ``diff = D1 - D2``; each change is
    clipped to ``max_change``.  Only pixels with ``|phi| <= band`` are updated (``band < 0``:
    all).
    """
    h, w = phi.shape
    eta = 1e-8
    worst = 0.0
    for i in range(h):
        im = max(i - 1, 0)
        ip = min(i + 1, h - 1)
        for j in range(w):
            p = phi[i, j]
            if band >= 0.0 and abs(p) > band:
                continue
            jm = max(j - 1, 0)
            jp = min(j + 1, w - 1)
            # Faces: right (j+1), left (j-1), down (i+1), up (i-1); x along j, y along i.
            dyc = 0.5 * (phi[ip, j] - phi[im, j])
            dxc = 0.5 * (phi[i, jp] - phi[i, jm])
            c_r = 1.0 / np.sqrt(eta + (phi[i, jp] - p) ** 2 + dyc * dyc)
            c_l = 1.0 / np.sqrt(
                eta + (p - phi[i, jm]) ** 2 + (0.5 * (phi[ip, jm] - phi[im, jm])) ** 2
            )
            c_d = 1.0 / np.sqrt(eta + (phi[ip, j] - p) ** 2 + dxc * dxc)
            c_u = 1.0 / np.sqrt(
                eta + (p - phi[im, j]) ** 2 + (0.5 * (phi[im, jp] - phi[im, jm])) ** 2
            )
            delta = 1.0 / (np.pi * (1.0 + p * p))
            k = dt * delta
            num = p + k * (
                mu * (c_r * phi[i, jp] + c_l * phi[i, jm] + c_d * phi[ip, j] + c_u * phi[im, j])
                - diff[i, j]
            )
            new = num / (1.0 + k * mu * (c_r + c_l + c_d + c_u))
            new = min(max(new, p - max_change), p + max_change)
            worst = max(worst, abs(new - p))
            phi[i, j] = new
    return worst
