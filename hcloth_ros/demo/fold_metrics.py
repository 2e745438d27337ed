"""
How well a cloth was folded in half: the fold demo's three measures.

The demo's client picks up the two near corners (smallest y) and lays them on the far
edge, so the near half of the rest rectangle (rest y below the middle) ends on top of the
far half. On the finest grid before and after (``(rows, cols, 3)``, rows along the
cloth's v axis, which the fold scene lays along +y):

* ``top_below``: points of the top layer (the near half) lower than the bottom layer under
  them: the bottom layer's height there is that of its point nearest in x and y; only top
  points over the bottom layer count (nearest bottom point within one grid spacing).
  0 means no part of the top half went through the bottom half.
* ``far_edge_moved``: how far the far edge's points moved at most (m), in 3-D.
* ``fold_line``, ``fold_offset``: where the crease lies (the folded cloth's smallest y)
  and how far that is from where the client put it, the middle of the rest rectangle (m).
"""

import numpy as np


def fold_metrics(before, after):
    """Return the measures of the module docstring as a dict of floats and ints."""
    before, after = np.asarray(before, float), np.asarray(after, float)
    rows = before.shape[0]
    top, bottom = after[:rows // 2].reshape(-1, 3), after[rows // 2 + 1:].reshape(-1, 3)
    spacing = np.linalg.norm(before[1, 0] - before[0, 0])
    below = 0
    for chunk in np.array_split(top, max(1, len(top) // 512)):
        d = np.linalg.norm(chunk[:, None, :2] - bottom[None, :, :2], axis=2)
        nearest = np.argmin(d, axis=1)
        over = d[np.arange(len(chunk)), nearest] < spacing
        below += int(np.sum(over & (chunk[:, 2] < bottom[nearest, 2])))
    middle = 0.5 * (before[..., 1].min() + before[..., 1].max())
    fold_line = float(after[..., 1].min())
    return {'top_below': below,
            'far_edge_moved': float(np.linalg.norm(after[-1] - before[-1], axis=1).max()),
            'fold_line': fold_line, 'fold_offset': abs(fold_line - middle)}


def describe(metrics):
    """Return one line for people: the three measures with their units."""
    return (f'fold: {metrics["top_below"]} top-layer points below the bottom layer, far '
            f'edge moved {metrics["far_edge_moved"] * 100:.1f} cm, crease at y = '
            f'{metrics["fold_line"]:.3f} m ({metrics["fold_offset"] * 100:.1f} cm from the '
            'middle)')
