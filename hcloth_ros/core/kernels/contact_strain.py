"""
Strain limiting for the contact rounds: points lying on an obstacle move along its surface.

The rounds of :meth:`~hcloth_ros.core.solvers.Solver._wrap` alternate strain limiting and
contact on a level draped over an obstacle. A spring bridging a box's edge (one end on the
top, the other on a side face) is shortened by moving its ends towards each other, into
the box; contact then pushes each end back out along its face's normal and undoes that
part of the correction, so the spring stays long: at 129 x 129 on the table scene these
springs sat at 0.17 mean strain (up to 0.29) while the springs beside them were within the
limit (issue 10's note). Here a point lying on an obstacle (within ``BAND`` of its grown
surface, outside it) moves only within the surface's tangent plane, or away from it, and
the spring's correction is scaled so that the moves it keeps shorten the spring to its
limit (position-based projection with the gradients restricted to those planes).

Gauss-Seidel over the structural and shear springs (stencil directions 0, 2, 4, 6), row
by row: each correction is seen by the next spring, so a correction travels along a flap
within one sweep instead of one point a sweep. Velocities and the step's velocity change
take each move divided by ``h``, as :mod:`~hcloth_ros.core.kernels.strain` does.
"""

import math

from hcloth_ros.core.kernels.jit import JIT
from hcloth_ros.core.kernels.layout import FREE, STENCIL_DC, STENCIL_DR
import numba
import numpy as np

# A point lies on an obstacle when it is within this distance (m) of its grown surface
# (the obstacle plus the contact margin), outside it: contact leaves points exactly on
# that surface, strain limiting a fraction of a millimetre off it.
BAND = 0.0005
# A spring whose kept moves shorten it by less than this fraction of a free spring's rate
# is skipped (both ends pinned against faces the spring is normal to: no move can help).
SMALLEST_RATE = 0.05
# The spring directions limited: right, down, down-right, down-left.
DIRECTIONS = np.array([0, 2, 4, 6])
STEP_ROWS = np.asarray(STENCIL_DR)[DIRECTIONS].astype(np.int64)
STEP_COLS = np.asarray(STENCIL_DC)[DIRECTIONS].astype(np.int64)


@numba.njit(**JIT)
def _normal(x, y, z, planes, boxes, spheres, margin):
    """
    Return the outward unit normal of the surface a point at (x, y, z) lies on (0: none).

    The planes are tried first, then the boxes' faces (a point on a box's top, within its
    x and y extent, takes +z; on a side face, below the top, that face's normal), then the
    spheres; the last one found counts.
    """
    nx, ny, nz = 0.0, 0.0, 0.0
    for p in range(planes.shape[0]):
        gap = x * planes[p, 0] + y * planes[p, 1] + z * planes[p, 2] - planes[p, 3] - margin
        if -BAND < gap < BAND:
            nx, ny, nz = planes[p, 0], planes[p, 1], planes[p, 2]
    for b in range(boxes.shape[0]):
        out_x = abs(x - boxes[b, 0]) - boxes[b, 3] - margin
        out_y = abs(y - boxes[b, 1]) - boxes[b, 4] - margin
        out_z = abs(z - boxes[b, 2]) - boxes[b, 5] - margin
        farthest = max(out_x, out_y, out_z)
        if not -BAND < farthest < BAND:
            continue    # away from it, or inside (contact's business)
        if out_z > -BAND:
            nx, ny, nz = 0.0, 0.0, 1.0 if z > boxes[b, 2] else -1.0
        elif out_x > -BAND:
            nx, ny, nz = 1.0 if x > boxes[b, 0] else -1.0, 0.0, 0.0
        else:
            nx, ny, nz = 0.0, 1.0 if y > boxes[b, 1] else -1.0, 0.0
    for s in range(spheres.shape[0]):
        dx, dy, dz = x - spheres[s, 0], y - spheres[s, 1], z - spheres[s, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist > 0.0 and abs(dist - spheres[s, 3] - margin) < BAND:
            nx, ny, nz = dx / dist, dy / dist, dz / dist
    return nx, ny, nz


@numba.njit(**JIT)
def _kept(q, r, c, mx, my, mz, planes, boxes, spheres, margin):
    """
    Return the move (mx, my, mz) of point (r, c) without its part into its surface.

    The surface is found where the point is now, not once a round: with the normals taken
    at the start of each round the 129 x 129 table drop reached 0.252 (0.171 this way) and
    0.105-0.211 over its last 3 s (``tools/table_flaps.py multigrid --levels 5 --option
    contact_strain=tangent --option contact_sweeps=100``, one run each), presumably as a
    point pulled off a face during the sweeps kept that face's normal.
    """
    nx, ny, nz = _normal(q[0, r, c], q[1, r, c], q[2, r, c], planes, boxes, spheres, margin)
    into = mx * nx + my * ny + mz * nz
    if into < 0.0:
        return mx - into * nx, my - into * ny, mz - into * nz
    return mx, my, mz


@numba.njit(**JIT)
def _shift(q, qd, dv, r, c, lam, mx, my, mz, h):
    """Move point (r, c) by ``lam`` times (mx, my, mz); its velocities follow."""
    for d, m in ((0, mx), (1, my), (2, mz)):
        q[d, r, c] += lam * m
        qd[d, r, c] += lam * m / h
        dv[d, r, c] += lam * m / h


@numba.njit(**JIT)
def tangent_strain_limit(q, qd, dv, rest, hold_kind, planes, boxes, spheres, margin,
                         max_stretch, max_sweeps, tolerance, h):
    """
    Limit the springs of a level to ``(1 + max_stretch)`` times their rest length.

    Gauss-Seidel sweeps (see the module docstring), every free point movable, a point
    lying on an obstacle of the scene's arrays only along its surface (where it lies
    when its spring is corrected). Stops
    after a sweep that found no spring over its limit by more than ``tolerance``
    (relative); returns how many sweeps corrected a spring (0: none over).
    """
    rows, cols = hold_kind.shape
    corrected = 0
    for _ in range(max_sweeps):
        over = False
        for r in range(rows):
            for c in range(cols):
                wp = 1.0 if hold_kind[r, c] == FREE else 0.0
                for e in range(STEP_ROWS.shape[0]):
                    r2, c2 = r + STEP_ROWS[e], c + STEP_COLS[e]
                    if r2 < 0 or r2 >= rows or c2 < 0 or c2 >= cols:
                        continue
                    wn = 1.0 if hold_kind[r2, c2] == FREE else 0.0
                    limit = rest[DIRECTIONS[e]] * (1.0 + max_stretch)
                    dx = q[0, r2, c2] - q[0, r, c]
                    dy = q[1, r2, c2] - q[1, r, c]
                    dz = q[2, r2, c2] - q[2, r, c]
                    length = math.sqrt(dx * dx + dy * dy + dz * dz)
                    if wp + wn == 0.0 or not length > limit * (1.0 + tolerance):
                        continue
                    over = True
                    ux, uy, uz = dx / length, dy / length, dz / length
                    ax, ay, az = _kept(q, r, c, wp * ux, wp * uy, wp * uz, planes, boxes,
                                       spheres, margin)
                    bx, by, bz = _kept(q, r2, c2, -wn * ux, -wn * uy, -wn * uz, planes,
                                       boxes, spheres, margin)
                    # how fast the kept moves shorten the spring (to first order)
                    rate = (ax - bx) * ux + (ay - by) * uy + (az - bz) * uz
                    if rate < SMALLEST_RATE * (wp + wn):
                        continue
                    lam = (length - limit) / rate
                    _shift(q, qd, dv, r, c, lam, ax, ay, az, h)
                    _shift(q, qd, dv, r2, c2, lam, bx, by, bz, h)
        if not over:
            break
        corrected += 1
    return corrected
