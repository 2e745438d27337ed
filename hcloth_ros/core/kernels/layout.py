"""
The grid layout every kernel shares: the spring stencil, hold kinds and row chunks.

Each level is a regular grid; arrays are float64 ``(3, rows, cols)`` (x, y, z planes:
structure of arrays) or ``(rows, cols)``. Every point has up to 12 springs, one per entry
of the stencil below; ``rest`` and ``stiffness`` of a level are given per entry, shape
``(12,)``. Kernels gather: a point reads its neighbours and writes only its own entries,
so splitting rows among threads needs no atomics and results are the same bits run after
run.

Compile time: loops over stencil entries, components or spring terms that hold an inner
loop take their trip count from an array's shape (``stiffness.shape[0]``,
``q.shape[0]``), not from a constant. With a constant LLVM unrolls them fully and
vectorises every copy of the inner loop: one such 16-iteration copy loop cost 40 s of
compilation here, and no speed.
"""

from hcloth_ros.core.kernels.jit import JIT
import numba
import numpy as np


# The 12-spring stencil as (row offset, column offset), in pairs of opposite directions:
# structural along u, structural along v, the two shear diagonals, bending along u,
# bending along v. Entry 2 j + 1 is the opposite of entry 2 j (the same spring seen from
# its other end).
STENCIL_DR = np.array([0, 0, 1, -1, 1, -1, 1, -1, 0, 0, 2, -2], dtype=np.int64)
STENCIL_DC = np.array([1, -1, 0, 0, 1, -1, -1, 1, 2, -2, 0, 0], dtype=np.int64)
STENCIL_SIZE = 12
# Entries 0 .. 7 are the structural and shear springs (strain limiting, strain metrics).
STRETCH_SIZE = 8

# Hold kinds (see hcloth_ros.core.control): a held point's velocity change is prescribed.
FREE = 0
PINNED = 1
DRIVEN = 2

# Levels with fewer points run in one chunk (one thread): splitting costs more there.
PAR_MIN_POINTS = 2048
# Most row chunks a parallel kernel splits a level into.
MAX_CHUNKS = 8


@numba.njit(**JIT)
def chunk_count(rows, cols):
    """
    Row chunks a kernel splits a level into for ``prange``.

    1 (one thread) below ``PAR_MIN_POINTS`` points, else about 32 rows a chunk, 2 to
    ``MAX_CHUNKS`` of them (``prange`` hands each thread a contiguous run of chunks). Not
    ``numba.get_num_threads()``: a kernel calling it cannot be cached.
    """
    if rows * cols < PAR_MIN_POINTS:
        return 1
    return max(2, min(MAX_CHUNKS, rows // 32))


@numba.njit(**JIT)
def stencil_span(r, s, rows, cols):
    """
    Columns ``lo .. hi-1`` of row r whose neighbour in stencil direction s exists.

    ``hi <= lo`` when the neighbour row is outside the grid. Looping over whole spans of
    columns (not point by point with a bounds check) lets LLVM vectorise the loops.
    """
    rr = r + STENCIL_DR[s]
    if rr < 0 or rr >= rows:
        return 0, 0
    dc = STENCIL_DC[s]
    return max(0, -dc), min(cols, cols - dc)


@numba.njit(**JIT)
def row3(a, r, c):
    """
    Return the x, y and z rows of ``a[:, r, c:]``: 1-D contiguous views from column c.

    Views that start at the first column a loop reads keep every index ``i >= 0``, which
    lets LLVM drop numba's negative-index handling and vectorise.
    """
    return a[0, r, c:], a[1, r, c:], a[2, r, c:]


@numba.njit(**JIT)
def clear3(x, y, z):
    """
    Zero three 1-D buffers of the same length.

    A loop: numba's slice assignment costs a second of compilation.
    """
    for i in range(x.shape[0]):
        x[i] = 0.0
        y[i] = 0.0
        z[i] = 0.0


@numba.njit(**JIT)
def advance_row(x, v, dv, h, x_out, v_out):
    """Semi-implicit update of one row and component: ``v' = v + dv``, ``x' = x + h v'``."""
    for i in range(x.shape[0]):
        w = v[i] + dv[i]
        v_out[i] = w
        x_out[i] = x[i] + h * w


@numba.njit(**JIT)
def interleaved_dot(x, y, n):
    """
    ``sum_i x[i] y[i]`` over ``i < n`` in eight interleaved partial sums.

    A sequential sum cannot vectorise (every add waits for the previous one); eight
    independent sums can. The order is fixed, so the result is the same bits every run.
    """
    p0 = p1 = p2 = p3 = p4 = p5 = p6 = p7 = 0.0
    whole = n - n % 8
    for i in range(0, whole, 8):
        p0 += x[i] * y[i]
        p1 += x[i + 1] * y[i + 1]
        p2 += x[i + 2] * y[i + 2]
        p3 += x[i + 3] * y[i + 3]
        p4 += x[i + 4] * y[i + 4]
        p5 += x[i + 5] * y[i + 5]
        p6 += x[i + 6] * y[i + 6]
        p7 += x[i + 7] * y[i + 7]
    for i in range(whole, n):
        p0 += x[i] * y[i]
    return ((p0 + p1) + (p2 + p3)) + ((p4 + p5) + (p6 + p7))
