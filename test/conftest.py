"""Shared fixtures of the core tests: JIT warm-up once per session."""

import pytest

from hcloth_ros.core import warm_up


@pytest.fixture(scope='session', autouse=True)
def jit_warm():
    """Compile (or load from the numba cache) every kernel once, so that the timings of
    the tests themselves are not dominated by compilation."""
    return warm_up()
