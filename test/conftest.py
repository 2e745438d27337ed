"""Shared fixtures: JIT warm-up once per session, the paths the linters check."""

import os

from hcloth_ros.core import warm_up
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope='session', autouse=True)
def jit_warm():
    """
    Compile (or load from the numba cache) every kernel once.

    So that the timings of the tests themselves are not dominated by compilation.
    """
    return warm_up(self_contact=True, bodies=True, tangent_strain=True)


@pytest.fixture
def lint_paths():
    """Return the package's Python sources: the product, launch files, tests and tools."""
    return [os.path.join(ROOT, p) for p in ('hcloth_ros', 'launch', 'test', 'tools',
                                            'setup.py')]
