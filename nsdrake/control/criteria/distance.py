"""Exact distances between links' axis segments and a convex obstacle, in closed form.

A capsule link is its axis segment S(s) = A + s (B − A), s ∈ [0, 1], swollen by its
radius r (a sphere link: A = B). Its distance to a convex obstacle o is

    d = min_s φ_o(S(s)) − r,

with φ_o the signed distance to o, convex along the segment. For the shapes here the
minimum has a closed form, so no iteration and no geometry engine is needed:

- a sphere of radius R at C: φ(p) = ‖p − C‖ − R, minimised at the segment point
  nearest C;
- a box of half-sizes h in its frame O: outside the box,
  φ(p)² = Σ_i max(|p_i| − h_i, 0)², a convex piecewise-quadratic function of s with
  breakpoints where a coordinate crosses ±h_i; on each piece it is one quadratic,
  minimised exactly.

Each function takes the segments of every link at once, (k, 3) arrays of A and B in
the world, and returns a (k, 7) array of rows [φ, ∇φ (3), S (3)]: φ at the minimiser
S, the unit gradient ∇φ there (world), and S (world). A row whose segment touches or
enters the obstacle (φ ≤ TOUCH) has φ = NaN: there the normal is not unique and
the caller uses a general method. ∂d/∂q = ∇φ(S)ᵀ J_S by the envelope theorem
(:mod:`nsdrake.control.criteria.obstacle`).

The kernels are compiled with numba (``cache=True``: the first run in a fresh
install compiles them, about two seconds, and stores the result beside this file;
later processes load it). A hundred small numpy calls per pair would cost more
than the rest of the controller.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

TOUCH = 1e-12  # [m] at or below this the segment counts as touching: no unique normal


@njit(cache=True, inline="always")
def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


@njit(cache=True, inline="always")  # inlined: a kernel of its own compiled once per literal transpose
def _rotate(R, x, transpose):
    """R x, or Rᵀ x (3-vectors; no BLAS inside numba)."""
    out = np.empty(3)
    _rotate_into(R, x, transpose, out)
    return out


@njit(cache=True, inline="always")
def _rotate_into(R, x, transpose, out):
    """out = R x, or Rᵀ x (3-vectors)."""
    for i in range(3):
        if transpose:
            out[i] = R[0, i] * x[0] + R[1, i] * x[1] + R[2, i] * x[2]
        else:
            out[i] = R[i, 0] * x[0] + R[i, 1] * x[1] + R[i, 2] * x[2]


@njit(cache=True)
def segments_sphere(A, B, C, R):
    """Rows [φ, ∇φ, S] (module docstring) for segments A[k]B[k] and the sphere (C, R)."""
    out = np.empty((A.shape[0], 7))
    b, c, d = np.empty(3), np.empty(3), np.empty(3)  # reused: no allocation per segment
    for k in range(A.shape[0]):
        for i in range(3):
            b[i], c[i] = B[k, i] - A[k, i], C[i] - A[k, i]
        bb = _dot(b, b)
        s = 0.0 if bb == 0.0 else min(1.0, max(0.0, _dot(c, b) / bb))
        for i in range(3):
            out[k, 4 + i] = A[k, i] + s * b[i]
            d[i] = out[k, 4 + i] - C[i]
        norm = math.sqrt(_dot(d, d))
        out[k, 0] = norm - R if norm - R > TOUCH else np.nan
        for i in range(3):
            out[k, 1 + i] = d[i] / norm if norm > 0.0 else d[i]
    return out


@njit(cache=True)
def segments_box(A, B, R_WO, p_WO, h):
    """Rows [φ, ∇φ, S] (module docstring) for segments A[k]B[k] and the box of
    half-sizes h (3,) at pose (R_WO (3, 3), p_WO (3,))."""
    out = np.empty((A.shape[0], 7))
    a, b, x, cuts = np.empty(3), np.empty(3), np.empty(3), np.empty(8)  # reused per segment
    for k in range(A.shape[0]):
        for i in range(3):
            x[i] = A[k, i] - p_WO[i]
        _rotate_into(R_WO, x, True, a)  # the segment in the box frame: a + s b
        for i in range(3):
            x[i] = B[k, i] - A[k, i]
        _rotate_into(R_WO, x, True, b)
        best_s = _box_minimiser(a, b, h, cuts)
        for i in range(3):
            u = a[i] + best_s * b[i]
            x[i] = u - min(h[i], max(-h[i], u))  # u minus its projection on the box
        norm = math.sqrt(_dot(x, x))
        out[k, 0] = norm if norm > TOUCH else np.nan
        if norm > 0.0:
            for i in range(3):
                x[i] = x[i] / norm
            _rotate_into(R_WO, x, False, b)
            out[k, 1:4] = b
        else:
            out[k, 1:4] = x
        for i in range(3):
            out[k, 4 + i] = A[k, i] + best_s * (B[k, i] - A[k, i])
    return out


@njit(cache=True, inline="always")
def _box_minimiser(a, b, h, cuts):
    """The s ∈ [0, 1] minimising φ² along a + s b (box frame): φ² is one quadratic between
    the breakpoints where a coordinate crosses ±h_i, minimised exactly on each piece.
    ``cuts`` (8,) is scratch."""
    cuts[0], cuts[1] = 0.0, 1.0
    count = 2
    for i in range(3):
        if b[i] != 0.0:
            for edge in (h[i], -h[i]):
                s = (edge - a[i]) / b[i]
                if 0.0 < s < 1.0:
                    cuts[count] = s
                    count += 1
    for j in range(1, count):  # insertion sort of the few breakpoints
        value, i = cuts[j], j - 1
        while i >= 0 and cuts[i] > value:
            cuts[i + 1] = cuts[i]
            i -= 1
        cuts[i + 1] = value
    best_f, best_s = np.inf, 0.0
    for j in range(count - 1):
        lo, hi = cuts[j], cuts[j + 1]
        if hi <= lo:
            continue
        mid = 0.5 * (lo + hi)
        qa = qb = qc = 0.0  # f(s) = qa s² + qb s + qc on this piece
        for i in range(3):
            u = a[i] + mid * b[i]
            if u > h[i]:
                c = a[i] - h[i]
            elif u < -h[i]:
                c = a[i] + h[i]
            else:
                continue
            qa += b[i] * b[i]
            qb += 2.0 * c * b[i]
            qc += c * c
        s = lo if qa == 0.0 else min(hi, max(lo, -qb / (2.0 * qa)))
        f = (qa * s + qb) * s + qc
        if f < best_f:
            best_f, best_s = f, s
    return best_s
