"""
What reading never-written zeroed memory costs here: eq. 7 on the 257 x 257 level, timed.

    .venv/bin/python tools/zero_page.py

Runs eq. 7's kernel (one thread) on the node's 257 x 257 refinement level twice: with the
prescribed velocity changes in an array from ``np.zeros`` that nothing wrote (as the
solvers held it before :mod:`hcloth_ros.core.buffers`: only held points' entries are ever
written, the free ones are only read), and in one from ``buffers.zeros``. Prints the
median of ``--calls`` calls of each. On a machine where the zero page costs nothing the
two are equal.
"""

import argparse
import time

from hcloth_ros import params
from hcloth_ros.core import buffers
import numba
import numpy as np


def median_ms(call, calls):
    """Return the median wall time of ``call()`` over ``calls`` calls (ms), after one."""
    call()
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--calls', type=int, default=100)
    args = parser.parse_args(argv)
    numba.set_num_threads(1)
    values = params.resolve({'cloth.levels': 6, 'solver.accurate_level': 3})
    model, solver, state, control = params.build_all(values)
    k, h = model.level_count - 1, float(values['solver.dt'])
    lv, kit, holds = model.level(k), solver.kernels(k), control.holds(k)
    coarse = [a.copy() for a in (state.q[k - 1], state.qd[k - 1], state.qd[k - 1])]
    outputs = [buffers.zeros(state.q[k].shape) for _ in range(3)]

    def eq7(prescribed):
        kit.eq7_level(state.q[k], state.qd[k], lv.mass, lv.rest, lv.stiffness,
                      lv.contraction, solver.dinv(k, h), holds.kind, prescribed, h,
                      model.gravity, False, *coarse, state.q[k - 1], False,
                      *outputs)

    unwritten = np.zeros(state.q[k].shape)
    written = buffers.zeros(state.q[k].shape)
    slow = median_ms(lambda: eq7(unwritten), args.calls)
    fast = median_ms(lambda: eq7(written), args.calls)
    print(f'eq. 7 on {lv.rows} x {lv.cols}, one thread, median of {args.calls} calls: '
          f'np.zeros never written {slow:.2f} ms, buffers.zeros {fast:.2f} ms '
          f'({slow / fast:.1f}x)')


if __name__ == '__main__':
    main()
