"""
Static obstacles the cloth rests on: planes, axis-aligned boxes and spheres.

A point that ends a step inside an obstacle (grown by ``margin``, the cloth's half
thickness) is moved to the nearest surface point; the normal velocity into the obstacle is
removed and Coulomb friction slows the tangential velocity by ``friction`` times the
removed normal speed (a kinetic friction impulse, capped so it never reverses motion).
"""

from dataclasses import dataclass

import numpy as np

# distance kept from obstacle surfaces by default (m): about a cloth's half thickness
MARGIN = 0.002


@dataclass(frozen=True)
class Scene:
    """
    Obstacles as packed float64 arrays (the layout the contact kernel reads).

    :ivar planes: ``(P, 4)``: unit normal ``n`` and offset ``d``; the free side is
        ``n . x >= d``.
    :ivar boxes: ``(B, 6)``: centre and half extents of axis-aligned boxes (m).
    :ivar spheres: ``(S, 4)``: centre and radius (m).
    :ivar friction: Coulomb coefficient, >= 0.
    :ivar margin: distance kept from every surface (m), >= 0.
    """

    planes: np.ndarray
    boxes: np.ndarray
    spheres: np.ndarray
    friction: float = 0.5
    margin: float = MARGIN

    @property
    def empty(self):
        return len(self.planes) + len(self.boxes) + len(self.spheres) == 0


def make_scene(ground_z=None, boxes=(), spheres=(), friction=0.5, margin=MARGIN):
    """
    Build a :class:`Scene`, checking every number.

    :param ground_z: height of a ground plane with normal +z, or None for no ground.
    :param boxes: iterable of ``(cx, cy, cz, hx, hy, hz)``.
    :param spheres: iterable of ``(cx, cy, cz, radius)``.
    """
    planes = np.zeros((0, 4))
    if ground_z is not None:
        if not np.isfinite(ground_z):
            raise ValueError(f'ground_z must be finite, got {ground_z}')
        planes = np.array([[0.0, 0.0, 1.0, float(ground_z)]])
    box_arr = np.asarray(list(boxes), dtype=np.float64).reshape(-1, 6)
    sphere_arr = np.asarray(list(spheres), dtype=np.float64).reshape(-1, 4)
    for name, arr in (('box', box_arr), ('sphere', sphere_arr)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f'{name} values must be finite')
    if np.any(box_arr[:, 3:] <= 0):
        raise ValueError('box half extents must be positive')
    if np.any(sphere_arr[:, 3] <= 0):
        raise ValueError('sphere radii must be positive')
    if not (np.isfinite(friction) and friction >= 0):
        raise ValueError(f'friction must be >= 0, got {friction}')
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f'margin must be >= 0, got {margin}')
    arrays = [np.ascontiguousarray(a) for a in (planes, box_arr, sphere_arr)]
    for a in arrays:
        a.setflags(write=False)
    return Scene(*arrays, friction=float(friction), margin=float(margin))


def empty_scene():
    return make_scene()
