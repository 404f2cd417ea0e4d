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


@njit(cache=True)
def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


@njit(cache=True)
def _rotate(R, x, transpose):
    """R x, or Rᵀ x (3-vectors; no BLAS inside numba)."""
    out = np.empty(3)
    for i in range(3):
        if transpose:
            out[i] = R[0, i] * x[0] + R[1, i] * x[1] + R[2, i] * x[2]
        else:
            out[i] = R[i, 0] * x[0] + R[i, 1] * x[1] + R[i, 2] * x[2]
    return out


@njit(cache=True)
def segments_sphere(A, B, C, R):
    """Rows [φ, ∇φ, S] (module docstring) for segments A[k]B[k] and the sphere (C, R)."""
    out = np.empty((A.shape[0], 7))
    for k in range(A.shape[0]):
        b = B[k] - A[k]
        c = C - A[k]
        bb = _dot(b, b)
        s = 0.0 if bb == 0.0 else min(1.0, max(0.0, _dot(c, b) / bb))
        d = A[k] + s * b - C
        norm = math.sqrt(_dot(d, d))
        out[k, 0] = norm - R if norm - R > TOUCH else np.nan
        out[k, 1:4] = d / norm if norm > 0.0 else d
        out[k, 4:7] = A[k] + s * b
    return out


@njit(cache=True)
def segments_box(A, B, R_WO, p_WO, h):
    """Rows [φ, ∇φ, S] (module docstring) for segments A[k]B[k] and the box of
    half-sizes h (3,) at pose (R_WO (3, 3), p_WO (3,))."""
    out = np.empty((A.shape[0], 7))
    cuts = np.empty(8)
    for k in range(A.shape[0]):
        a = _rotate(R_WO, A[k] - p_WO, True)  # the segment in the box frame: a + s b
        b = _rotate(R_WO, B[k] - A[k], True)
        cuts[0], cuts[1] = 0.0, 1.0
        count = 2
        for i in range(3):
            if b[i] != 0.0:
                for edge in (h[i], -h[i]):
                    s = (edge - a[i]) / b[i]
                    if 0.0 < s < 1.0:
                        cuts[count] = s
                        count += 1
        pieces = np.sort(cuts[:count])
        best_f, best_s = np.inf, 0.0
        for j in range(count - 1):
            lo, hi = pieces[j], pieces[j + 1]
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
        u = a + best_s * b
        diff = u - np.minimum(h, np.maximum(-h, u))
        norm = math.sqrt(_dot(diff, diff))
        out[k, 0] = norm if norm > TOUCH else np.nan
        out[k, 1:4] = _rotate(R_WO, diff / norm, False) if norm > 0.0 else diff
        out[k, 4:7] = A[k] + best_s * (B[k] - A[k])
    return out
