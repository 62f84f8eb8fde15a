"""The friction disk's local problem: the minimizer of a 2-D quadratic over a disk.

Every cone-model friction update of :mod:`contactlab.lcp.friction` (``nsgs``, ``staggered``, and
so Newton's watchdog sweeps) solves, for one contact with its normal impulse r_N fixed::

    minimize ½ r_Tᵀ W_TT r_T + bᵀ r_T   over   ‖r_T‖ ≤ μ r_N

(W_TT: the 2×2 tangential block of W_αα [velocity / impulse]; b: the tangential velocity that does
not come from this contact's own friction [velocity]; r_T [impulse]). It is a trust-region
subproblem, solved here by the secular equation in Moré and Sorensen's form. μ r_N spans every
float, down to subnormal numbers (μ = 2.2e-308 came from a property test), so the equation is
solved in units of the radius, where nothing overflows (:func:`disk_solve`).
"""

from __future__ import annotations

import math

from ..compiling import njit


@njit(cache=True)
def _length(x, y):
    """‖(x, y)‖₂ without the underflow or overflow of x² + y² (|x| ~ 1e-160 or 1e160); math.hypot,
    which avoids both, is about twice as slow, so it serves only there."""
    squared = x * x + y * y
    if 1e-290 < squared < 1e290:
        return math.sqrt(squared)
    return math.hypot(x, y)


@njit(cache=True)
def disk_solve(
    a00: float, a01: float, a10: float, a11: float, b1: float, b2: float, radius: float
) -> tuple[float, float]:
    """Minimizer of ½ xᵀ A x + bᵀ x over ‖x‖ ≤ radius (A 2×2, symmetric part PSD): returns (x1, x2).

    Unconstrained if that lies in the disk, else (A + νI) x = −b with ν > 0 chosen by safeguarded
    Newton on 1/‖x(ν)‖ − 1/radius (Moré-Sorensen), solved for z = x / radius on the unit circle:
    ``(t A + σ I) z = −b/‖b‖`` with t = radius/‖b‖ and σ = t ν (divided through by t·Σ|a_ij| when
    that exceeds 1). Every quantity is then of order one whatever the radius: in x itself, 1/radius
    overflows once μ r_N is subnormal (the iteration returned NaN there, and Gauss-Seidel stalled on
    it), while in z a disk far smaller than ‖b‖/‖A‖ simply gives t A ≈ 0 and z → −b/‖b‖, the limit
    of a frictionless contact's r_T = 0 approached continuously."""
    if radius <= 0.0:
        return 0.0, 0.0
    norm_b = _length(b1, b2)
    if norm_b == 0.0:
        return 0.0, 0.0
    scale = abs(a00) + abs(a11) + abs(a01) + abs(a10)
    det = a00 * a11 - a01 * a10
    if det > 1e-13 * scale * scale:
        x1 = -(a11 * b1 - a01 * b2) / det
        x2 = -(-a10 * b1 + a00 * b2) / det
        squared_radius = radius * radius  # compare squares (no square root) unless they leave the normal range
        if x1 * x1 + x2 * x2 <= squared_radius if 1e-290 < squared_radius < 1e290 else _length(x1, x2) <= radius:
            return x1, x2
    if scale == 0.0:  # A = 0: a linear objective, least at the point of the circle against b
        return -radius * (b1 / norm_b), -radius * (b2 / norm_b)
    # the scaled problem (C + σI) z = −c, ‖z‖ = 1, with C's entries and c at most of order one
    t = radius / norm_b
    c1 = b1 / norm_b
    c2 = b2 / norm_b
    norm_c = 1.0
    if t * scale <= 1.0:
        c00, c01, c10, c11 = t * a00, t * a01, t * a10, t * a11
    else:  # a disk far larger than ‖b‖/‖A‖ (A nearly singular): scale A to order one instead
        c00, c01, c10, c11 = a00 / scale, a01 / scale, a10 / scale, a11 / scale
        c1 = c1 / scale / t
        c2 = c2 / scale / t
        norm_c = _length(c1, c2)
    # smallest eigenvalue of the symmetric part, to bound σ from above
    s01 = 0.5 * (c01 + c10)
    half_tr = 0.5 * (c00 + c11)
    low_eig = half_tr - math.sqrt(0.25 * (c00 - c11) ** 2 + s01 * s01)
    lo = max(0.0, -low_eig)
    hi = norm_c + max(0.0, -low_eig) * 2.0 + 1e-300
    sigma = lo
    z1 = 0.0
    z2 = 0.0
    for _ in range(100):
        if sigma <= lo or sigma >= hi:
            sigma = 0.5 * (lo + hi)
        m00 = c00 + sigma
        m11 = c11 + sigma
        d = m00 * m11 - c01 * c10
        if d <= 0.0:
            lo = sigma
            sigma = 0.5 * (lo + hi)
            continue
        z1 = -(m11 * c1 - c01 * c2) / d
        z2 = -(-c10 * c1 + m00 * c2) / d
        nz = _length(z1, z2)
        if abs(nz - 1.0) <= 1e-15:
            break
        if nz == 0.0:
            # c underflowed (a disk some 1e300 times ‖b‖/‖A‖ and A singular): with no linear term
            # left, z minimizes ½ zᵀCz on the unit circle, the eigenvector of the symmetric part's
            # smallest eigenvalue, taken against b
            v1, v2 = s01, low_eig - c00
            if _length(low_eig - c11, s01) > _length(v1, v2):
                v1, v2 = low_eig - c11, s01
            norm_v = _length(v1, v2)
            if norm_v == 0.0:  # C = λI: every direction is one
                v1, v2, norm_v = -b1, -b2, norm_b
            if v1 * b1 + v2 * b2 > 0.0:
                norm_v = -norm_v
            z1 = v1 / norm_v
            z2 = v2 / norm_v
            break
        phi = 1.0 / nz - 1.0
        if phi < 0.0:
            lo = sigma
        else:
            hi = sigma
        # dz/dσ = −(C + σI)⁻¹ z
        y1 = -(m11 * z1 - c01 * z2) / d
        y2 = -(-c10 * z1 + m00 * z2) / d
        dnz = (z1 * y1 + z2 * y2) / nz
        dphi = -dnz / nz / nz  # not / (nz * nz), which underflows where c is tiny
        if dphi > 0.0:
            sigma = sigma - phi / dphi
        else:
            sigma = 0.5 * (lo + hi)
        if hi - lo <= 1e-16 * max(hi, 1e-300):
            break
    nz = _length(z1, z2)
    if nz > 1.0:
        z1 /= nz
        z2 /= nz
    return radius * z1, radius * z2
