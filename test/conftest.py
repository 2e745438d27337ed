"""Shared fixtures: JIT warm-up once per session, the paths the linters check; tools."""

import functools
import importlib.util
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


@functools.lru_cache(maxsize=None)
def load_tool(name):
    """
    Return ``tools/<name>.py`` (not installed) as a module, loaded once.

    Once: ``tools/intersections.py``'s kernels are not cached and compile at each load
    (1.3 s), which made the 129 x 129 double fold's test take 85 s instead of 15.
    """
    path = os.path.join(ROOT, 'tools', name + '.py')
    spec = importlib.util.spec_from_file_location(name, path)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool
