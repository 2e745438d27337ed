"""
Where a level's cloth passes through itself: its edges through its own triangles.

    from tools.intersections import intersections
    count, per_point = intersections(q)        # q: (3, rows, cols)

A check of a state, not of a step: an edge (along a row, down a column or a cell's
diagonal) whose ends lie on opposite sides of a triangle's plane and whose line passes
inside the triangle (exact orientation signs), the triangle not within ``RING`` rows and
columns of the edge's ends (as the self-contact kernel skips them). Self-contact keeps
points away from triangles; a tangle where no point crossed a triangle (a layer's corner
hooked round another layer's edge) shows here and nowhere else. ``per_point`` counts the
edges through triangles by the edge's first end (rows, cols). Brute force over a hash
grid of cells twice the grid spacing: about 0.1 s on 129 x 129.
"""

from hcloth_ros.core.kernels.self_contact import _orient, _triangle, RING
import numba
import numpy as np


@numba.njit(cache=False)
def _pierces(a, b, p, q, r):
    """Whether segment a-b passes through triangle p, q, r (strictly)."""
    if not _orient(p, q, r, a) * _orient(p, q, r, b) < 0.0:
        return False
    s1, s2, s3 = _orient(a, b, p, q), _orient(a, b, q, r), _orient(a, b, r, p)
    return (s1 > 0 and s2 > 0 and s3 > 0) or (s1 < 0 and s2 < 0 and s3 < 0)


@numba.njit(cache=False)
def _cells(x, vs, low, cell, out):
    """Write the hash cells (min ijk, max ijk) of the box of points ``vs``."""
    for d in range(3):
        mn, mx = np.inf, -np.inf
        for v in vs:
            mn, mx = min(mn, x[d, v]), max(mx, x[d, v])
        out[d], out[3 + d] = int((mn - low[d]) / cell), int((mx - low[d]) / cell)


@numba.njit(cache=False)
def _count(x, rows, cols, cell):
    low = np.empty(3)
    dims = np.empty(3, np.int64)
    for d in range(3):
        low[d] = x[d].min() - 1e-9
        dims[d] = int((x[d].max() - low[d]) / cell) + 1
    triangles = 2 * (rows - 1) * (cols - 1)
    boxes = np.empty((triangles, 6), np.int64)
    starts = np.zeros(dims[0] * dims[1] * dims[2] + 1, np.int64)
    for t in range(triangles):
        _cells(x, _triangle(t, cols), low, cell, boxes[t])
        b = boxes[t]
        for i in range(b[0], b[3] + 1):
            for j in range(b[1], b[4] + 1):
                for k in range(b[2], b[5] + 1):
                    starts[(i * dims[1] + j) * dims[2] + k + 1] += 1
    starts = np.cumsum(starts)
    fill = starts.copy()
    items = np.empty(starts[-1], np.int64)
    for t in range(triangles):
        b = boxes[t]
        for i in range(b[0], b[3] + 1):
            for j in range(b[1], b[4] + 1):
                for k in range(b[2], b[5] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    items[fill[c]] = t
                    fill[c] += 1
    per_point = np.zeros((rows, cols), np.int64)
    seen = np.full(triangles, -1, np.int64)
    box = np.empty(6, np.int64)
    edge = 0
    for r in range(rows):
        for c in range(cols):
            for direction in range(3):
                r2, c2 = (r, c + 1) if direction == 0 else \
                    ((r + 1, c) if direction == 1 else (r + 1, c + 1))
                if r2 >= rows or c2 >= cols:
                    continue
                a, b = r * cols + c, r2 * cols + c2
                edge += 1
                _cells(x, (a, b), low, cell, box)
                for i in range(box[0], box[3] + 1):
                    for j in range(box[1], box[4] + 1):
                        for k in range(box[2], box[5] + 1):
                            h = (i * dims[1] + j) * dims[2] + k
                            for m in range(starts[h], starts[h + 1]):
                                t = items[m]
                                if seen[t] == edge:
                                    continue
                                seen[t] = edge
                                tr, tc = (t // 2) // (cols - 1), (t // 2) % (cols - 1)
                                if tr - RING <= r2 and r <= tr + 1 + RING and \
                                        tc - RING <= max(c, c2) and min(c, c2) <= tc + 1 + RING:
                                    continue
                                p, q, s = _triangle(t, cols)
                                if _pierces(x[:, a], x[:, b], x[:, p], x[:, q], x[:, s]):
                                    per_point[r, c] += 1
    return per_point.sum(), per_point


def intersections(q):
    """Return ``(count, per_point)`` of a level ``q`` (3, rows, cols) (module docstring)."""
    rows, cols = q.shape[1], q.shape[2]
    x = np.ascontiguousarray(q).reshape(3, rows * cols)
    spacing = np.median(np.linalg.norm(q[:, :, 1:] - q[:, :, :-1], axis=0))
    # at most about 200 cells along the largest extent (a blown-up state stays cheap)
    extent = float(np.max(x.max(axis=1) - x.min(axis=1)))
    count, per_point = _count(x, rows, cols, max(2.0 * spacing, extent / 200.0, 1e-6))
    return int(count), per_point
