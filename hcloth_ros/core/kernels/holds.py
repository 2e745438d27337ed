"""Held points: the velocity change that makes them do what the control says."""

from hcloth_ros.core.kernels.jit import JIT
from hcloth_ros.core.kernels.layout import PINNED
import numba


@numba.njit(**JIT)
def prescribe(q, qd, hold_kind, drive_index, drive_target, h, prescribed_dv):
    """
    Velocity change of every held point for a step of ``h`` seconds.

    Pinned: ``-v``, so the new velocity is zero and ``x + h v`` is ``x`` bit for bit.
    Driven (flat grid indices ``drive_index``): the velocity that reaches
    ``drive_target[:, m]`` (m) at the end of the step. Entries of free points are left
    as they are.
    """
    rows, cols = hold_kind.shape
    for r in range(rows):
        kinds = hold_kind[r]
        pinned = 0
        for c in range(cols):       # a cheap scan first: most rows hold nothing
            pinned += kinds[c] == PINNED
        if pinned == 0:
            continue
        for c in range(cols):
            if kinds[c] == PINNED:
                for d in range(3):
                    prescribed_dv[d, r, c] = -qd[d, r, c]
    for m in range(drive_index.shape[0]):
        r, c = divmod(drive_index[m], cols)
        for d in range(3):
            prescribed_dv[d, r, c] = (drive_target[d, m] - q[d, r, c]) / h - qd[d, r, c]
