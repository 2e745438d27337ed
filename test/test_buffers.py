"""
The solvers keep their buffers in memory of their own, not in pages mapped to the zero page.

Reading never-written pages of ``np.zeros`` made eq. 7 on a 257 x 257 level six times
slower here (:mod:`hcloth_ros.core.buffers`). Whether a page was written shows in the
process's resident anonymous memory (``RssAnon``): a page only read maps the shared zero
page and is not counted, a written one is. So these tests assert resident bytes, which do
not depend on the machine's speed.
"""

import os

from hcloth_ros import params
from hcloth_ros.core import buffers
import numpy as np
import pytest

pytestmark = pytest.mark.skipif(not os.path.exists('/proc/self/status'),
                                reason='reads RssAnon from /proc (Linux)')
MB = 1 << 20


def _rss_anon():
    """Resident anonymous memory of this process in bytes."""
    with open('/proc/self/status') as status:
        for line in status:
            if line.startswith('RssAnon:'):
                return int(line.split()[1]) * 1024
    raise RuntimeError('no RssAnon in /proc/self/status')


def test_zeros_are_resident_and_numpy_zeros_only_read_are_not():
    before = _rss_anon()
    mine = buffers.zeros((3, 1024, 1024))           # 24 MB
    grown = _rss_anon() - before
    assert not mine.any()
    assert mine.dtype == np.float64 and mine.flags.c_contiguous
    assert grown >= 23 * MB
    # the mechanism the module works around: read, numpy's zeros stay unmapped
    before = _rss_anon()
    theirs = np.zeros((3, 1024, 1024))
    assert theirs.sum() == 0.0
    assert _rss_anon() - before < 4 * MB


def test_zeros_like_keeps_shape_and_dtype():
    like = buffers.zeros_like(np.ones((2, 3), dtype=np.int8))
    assert like.shape == (2, 3) and like.dtype == np.int8 and not like.any()


def test_the_solvers_buffers_are_resident_when_built():
    """A 257 x 257 multigrid solver's per-level buffers take resident memory at once."""
    values = params.resolve({'cloth.levels': 6, 'solver.accurate_level': 3})
    model = params.build_model(values)
    before = _rss_anon()
    solver = params.build_solver(model, values)
    grown = _rss_anon() - before
    names = ('_q', '_qd', '_dv', '_presc', '_scratch', '_a', '_integrated',
             '_x_hat', '_v_hat')
    per_level = sum(a.nbytes for name in names for a in getattr(solver, name))
    assert per_level > 16 * MB
    # everything the solver made is its own memory: at least the per-level buffers
    assert grown >= 0.95 * per_level
