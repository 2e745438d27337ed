"""Quantities the tests, benchmarks and recordings report about a cloth level."""

import numpy as np

from hcloth_ros.core import kernels


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
    """Mean absolute mean curvature of level k's interior (1/m): the wrinkle measure.

    At each interior grid point the discrete Laplacian of position (second differences
    over the rest spacings ``du``, ``dv``) is projected on the surface normal; half its
    magnitude is the mean curvature ``|H|``. A flat sheet scores 0, a sheet bent on a
    large radius R about ``1/(2R)``, and folds and wrinkles at the grid scale score far
    more, so comparing two runs on the same mesh tells which one wrinkles more (paper
    Fig. 6). Values depend on resolution: compare like with like.
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
    return float(np.mean(np.abs(np.einsum('drc,drc->rc', lap, n))) / 2)
