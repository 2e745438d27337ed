"""numpy's OpenBLAS limited to one thread beside numba's (hcloth_ros.core.blas)."""

import os

from hcloth_ros.core import blas
import numpy as np
import pytest


def test_the_loaded_openblas_runs_on_the_threads_asked_for():
    np.ones(4) @ np.ones(4)     # numpy's BLAS is loaded
    if not blas.openblas_threads():
        pytest.skip('numpy uses a BLAS other than OpenBLAS here')
    before = blas.openblas_threads()
    try:
        assert blas.limit_openblas_threads(2)
        assert set(blas.openblas_threads().values()) == {2}
        assert blas.limit_openblas_threads(1) == sorted(before)
        assert set(blas.openblas_threads().values()) == {1}
    finally:
        for path, count in before.items():
            blas.limit_openblas_threads(count)
    assert blas.openblas_threads() == before


def test_openblas_is_found_where_numpy_bundles_it():
    """The wheels' OpenBLAS (this venv's numpy) is the one the node must limit."""
    np.ones(4) @ np.ones(4)
    libs = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), 'numpy.libs')
    if not os.path.isdir(libs) or not any('openblas' in f for f in os.listdir(libs)):
        pytest.skip('numpy here is not a wheel with OpenBLAS bundled')
    assert any(p.startswith(libs) for p in blas.openblas_threads())
