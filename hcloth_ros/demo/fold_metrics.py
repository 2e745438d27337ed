"""
How well a cloth was folded in half: the fold demo's three measures.

The demo's client picks up the two near corners (smallest y) and lays them on the far
edge, so the near half of the rest rectangle (rest y below the middle) ends on top of the
far half. On the finest grid before and after (``(rows, cols, 3)``, rows along the
cloth's v axis, which the fold scene lays along +y):

* ``top_below``: points of the top layer (the near half) lower than the bottom layer
  under them: the bottom layer's surface height at the point's x and y, interpolated in
  the bottom layer's triangle that lies under it (the highest, if several do), by more
  than ``LEVEL`` (1 um: a point level with it is not through it); top points over no
  bottom triangle do not count. 0 means no part of the top half went through the bottom
  half. (The height of the nearest bottom point instead counted top-layer edge points
  lying beside a wrinkle of the bottom layer, up to 5 on a clean fold. A top-layer point
  lying on the ground at a crease flattened there, in the footprint of the bottom
  layer's first cell, on the ground too, is level with it: it counted as below by 2e-13
  m, the rounding of the interpolated height, without a ``LEVEL``, and by 1.8-3.9 nm at
  129 x 129 with 1 nm, in 5 of 8 folds with no edge through a triangle.)
* ``far_edge_moved``: how far the far edge's points moved at most (m), in 3-D.
* ``fold_line``, ``fold_offset``: where the crease lies (the folded cloth's smallest y)
  and how far that is from where the client put it, the middle of the rest rectangle (m).
"""

from hcloth_ros.core.model import grid_triangles
import numpy as np

# How far (m) a top-layer point must be below the bottom layer to count: beyond the
# nanometres by which two points on the ground differ, far within any thickness
LEVEL = 1e-6


def fold_metrics(before, after):
    """Return the measures of the module docstring as a dict of floats and ints."""
    before, after = np.asarray(before, float), np.asarray(after, float)
    rows = before.shape[0]
    top = after[:rows // 2].reshape(-1, 3)
    under = _height_under(after[rows // 2 + 1:], top[:, :2])
    below = int(np.sum(top[:, 2] < under - LEVEL))
    middle = 0.5 * (before[..., 1].min() + before[..., 1].max())
    fold_line = float(after[..., 1].min())
    return {'top_below': below,
            'far_edge_moved': float(np.linalg.norm(after[-1] - before[-1], axis=1).max()),
            'fold_line': fold_line, 'fold_offset': abs(fold_line - middle)}


def _height_under(grid, xy, chunk=256):
    """
    Return the height of a grid's surface under each of the points ``xy`` ``(n, 2)``.

    Interpolated in the triangles (two per cell) whose projection on the x-y plane holds
    the point, the highest where several do; -inf under no triangle.
    """
    tris = grid_triangles(*grid.shape[:2])
    a, b, cc = (grid.reshape(-1, 3)[tris[:, i]] for i in range(3))
    e, f = b[:, :2] - a[:, :2], cc[:, :2] - a[:, :2]
    det = e[:, 0] * f[:, 1] - f[:, 0] * e[:, 1]
    det = np.where(det == 0.0, np.nan, det)     # an edge-on triangle holds nothing
    heights = np.full(len(xy), -np.inf)
    for start in range(0, len(xy), chunk):
        g = xy[start:start + chunk, None, :] - a[None, :, :2]
        wb = (g[..., 0] * f[:, 1] - f[:, 0] * g[..., 1]) / det
        wc = (e[:, 0] * g[..., 1] - g[..., 0] * e[:, 1]) / det
        wa = 1.0 - wb - wc
        inside = (wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9)
        z = wa * a[:, 2] + wb * b[:, 2] + wc * cc[:, 2]
        heights[start:start + chunk] = np.where(inside, z, -np.inf).max(axis=1)
    return heights


def describe(metrics):
    """Return one line for people: the three measures with their units."""
    return (f'fold: {metrics["top_below"]} top-layer points below the bottom layer, far '
            f'edge moved {metrics["far_edge_moved"] * 100:.1f} cm, crease at y = '
            f'{metrics["fold_line"]:.3f} m ({metrics["fold_offset"] * 100:.1f} cm from the '
            'middle)')
