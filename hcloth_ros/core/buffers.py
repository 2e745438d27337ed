"""
Zeroed arrays whose memory is written, not only mapped: what the solvers keep between steps.

``np.zeros`` asks the C library for zeroed memory, and a large block comes straight from
the kernel as pages that all map one shared read-only zero page until they are first
written. Reading such pages is very slow on these machines (a virtual machine): eq. 7 on
the 257 x 257 level read the prescribed velocity changes of its free points, entries that
only a held point ever writes, and took 7.8 ms a call where the same call on written
memory takes 1.1 ms (one thread, ``tools/zero_page.py``); the node's whole 257 x 257 step
fell from 12.5 to 5.0 ms. Arrays made here are filled once, so every page is the
process's own from the start.
"""

import numpy as np


def zeros(shape, dtype=np.float64):
    """Return a zeroed array of ``shape`` whose pages have been written (see module)."""
    out = np.empty(shape, dtype=dtype)
    out.fill(0)
    return out


def zeros_like(a):
    """Return :func:`zeros` with ``a``'s shape and dtype."""
    return zeros(a.shape, a.dtype)
