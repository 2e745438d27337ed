"""Quantities the tests, benchmarks and recordings report about a cloth level."""

from hcloth_ros.core import kernels
from hcloth_ros.core.model import STENCIL_DC, STENCIL_DR
import numpy as np


def centre_of_mass(model, state, k):
    """Mass-weighted mean position of level k (m), shape ``(3,)``."""
    m = model.level(k).mass
    return np.einsum('drc,rc->d', state.q[k], m) / m.sum()


def centre_of_mass_velocity(model, state, k):
    m = model.level(k).mass
    return np.einsum('drc,rc->d', state.qd[k], m) / m.sum()


def energy(model, state, k):
    """``(kinetic, gravitational, elastic)`` energy of level k (J)."""
    lv = model.level(k)
    return kernels.energy(state.q[k], state.qd[k], lv.mass, lv.rest, lv.stiffness,
                          lv.contraction, model.gravity)


def strain(model, state, k):
    """``(max, mean)`` relative stretch of structural and shear springs on level k."""
    mx, mean, _ = kernels.strain_stats(state.q[k], state.qd[k], model.level(k).rest)
    return mx, mean


def wrinkliness(model, state, k):
    """
    Mean absolute mean curvature of level k's interior (1/m): the wrinkle measure.

    A flat sheet scores 0, a sheet bent on a large radius R about ``1/(2R)``, and folds
    and wrinkles at the grid scale score far more, so comparing two runs on the same mesh
    tells which one wrinkles more (paper Fig. 6). Values depend on resolution: compare
    like with like. See :func:`mean_curvature` for the per-point values.
    """
    return float(np.mean(mean_curvature(model, state, k)))


def mean_curvature(model, state, k):
    """
    ``|H|`` at each interior grid point of level k (1/m), shape ``(rows-2, cols-2)``.

    The discrete Laplacian of position (second differences over the rest spacings ``du``,
    ``dv``) projected on the surface normal; half its magnitude is the mean curvature.
    """
    lv = model.level(k)
    q = state.q[k]
    lap = ((q[:, 1:-1, :-2] + q[:, 1:-1, 2:] - 2 * q[:, 1:-1, 1:-1]) / lv.du ** 2
           + (q[:, :-2, 1:-1] + q[:, 2:, 1:-1] - 2 * q[:, 1:-1, 1:-1]) / lv.dv ** 2)
    tu = q[:, 1:-1, 2:] - q[:, 1:-1, :-2]
    tv = q[:, 2:, 1:-1] - q[:, :-2, 1:-1]
    n = np.cross(tu, tv, axis=0)
    norm = np.linalg.norm(n, axis=0)
    n = n / np.where(norm > 0, norm, 1.0)
    return np.abs(np.einsum('drc,drc->rc', lap, n)) / 2


def explicit_step_limit(model, k):
    """
    Return the largest stable step of symplectic Euler on level k at rest (s).

    That is 2 / sqrt(largest eigenvalue of M^-1 K), from dense eigenvalues: O(n^3), meant
    for up to ~1000 points.

    Symplectic Euler on a linear oscillator of frequency w is stable iff h w < 2; at rest
    each spring contributes k u u^T to the stiffness matrix (no transverse term).
    """
    lv = model.level(k)
    rest = model.rest_positions(k).reshape(3, -1).T
    n = lv.rows * lv.cols
    stiff = np.zeros((3 * n, 3 * n))
    for r in range(lv.rows):
        for c in range(lv.cols):
            i = r * lv.cols + c
            for s in range(12):
                rr, cc = r + STENCIL_DR[s], c + STENCIL_DC[s]
                if not (0 <= rr < lv.rows and 0 <= cc < lv.cols):
                    continue
                j = rr * lv.cols + cc
                u = rest[j] - rest[i]
                u /= np.linalg.norm(u)
                block = lv.stiffness[s] * np.outer(u, u)
                stiff[3 * i:3 * i + 3, 3 * i:3 * i + 3] += block
                stiff[3 * i:3 * i + 3, 3 * j:3 * j + 3] -= block
    minv_sqrt = np.repeat(1 / np.sqrt(lv.mass.ravel()), 3)
    lam = np.linalg.eigvalsh(minv_sqrt[:, None] * stiff * minv_sqrt[None, :]).max()
    return 2 / np.sqrt(lam)


def explicit_step_bound(model, k):
    """
    Return a cheap lower bound on :func:`explicit_step_limit` (s), for any mesh size.

    Gershgorin: every eigenvalue of M^-1 K is at most max_i 2 K_i / m_i, since row i of K
    holds K_i on the diagonal and springs summing to K_i off it.
    """
    lv = model.level(k)
    return float(2 / np.sqrt(np.max(2 * lv.stiffness_sum / lv.mass)))
