"""Time-varying cloth state: positions and velocities of every level."""

from hcloth_ros.core import buffers
from hcloth_ros.core.kernels import points_by_id_f32
import numpy as np


class State:
    """
    Positions ``q[k]`` and velocities ``qd[k]`` of each level k.

    Each is a C-contiguous float64 array of shape ``(3, rows, cols)`` (structure of
    arrays: x, y and z planes), in metres and metres per second, grid order. ``time`` is
    the simulated time in seconds.

    What a step does to the arrays: a solver writes the new state of every simulated level
    into buffers of its own and, if the step is accepted, swaps them in: afterwards
    ``q[k]`` and ``qd[k]`` are other array objects than before (the old ones become the
    solver's buffers and are overwritten by the next step), and ``time`` grows by ``dt``.
    Levels not simulated keep their arrays. So read positions through the state after
    every step (``state.q[k]``, :meth:`points`) and copy what you keep (:meth:`copy`);
    a reference to an array taken before a step is stale after it. A refused step leaves
    the arrays and the time as they were. :meth:`assign` copies values into the current
    arrays.
    """

    def __init__(self, q, qd, time=0.0):
        self.q = list(q)
        self.qd = list(qd)
        self.time = float(time)

    @classmethod
    def at_rest(cls, model):
        """Return the model's rest rectangle with zero velocity at every level."""
        q = [model.rest_positions(k) for k in range(model.level_count)]
        return cls(q, [buffers.zeros_like(a) for a in q])

    def copy(self):
        return State([a.copy() for a in self.q], [a.copy() for a in self.qd], self.time)

    def assign(self, other):
        """Copy ``other``'s values into this state's arrays."""
        for dst, src in zip(self.q + self.qd, other.q + other.qd):
            np.copyto(dst, src)
        self.time = other.time

    def points(self, k):
        """Level k positions as ``(rows * cols, 3)`` in grid order (a copy)."""
        return self.q[k].reshape(3, -1).T.copy()

    def velocities(self, k):
        return self.qd[k].reshape(3, -1).T.copy()

    def points_by_id(self, model, k):
        """Level k positions as ``(n_k, 3)`` in point-id order: row i is id i."""
        return self.points(k)[model.level(k).id_to_grid]

    def points_by_id_f32(self, model, k, out=None):
        """
        Level k positions as float32 ``(n_k, 3)`` in point-id order, for messages.

        One kernel pass (a cloud of 66k points every tick); ``out`` is reused if given.
        """
        lv = model.level(k)
        if out is None or out.shape != (lv.point_count, 3) or out.dtype != np.float32:
            out = np.empty((lv.point_count, 3), dtype=np.float32)
        points_by_id_f32(self.q[k], lv.id_to_grid, out)
        return out

    def position_of(self, model, point_id, k):
        g = model.grid_index(point_id, k)
        return self.q[k].reshape(3, -1)[:, g].copy()
