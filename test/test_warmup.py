"""Warm-up and the kernels' cache: what compiles, where it is cached, when it is stale."""

import importlib
import os
import shutil

from hcloth_ros.core import kernels
from hcloth_ros.core.kernels import jit
from hcloth_ros.core.warmup import kernel_calls
import numba


def test_shares_compile_exactly_the_signatures_the_warm_up_uses():
    """
    Check that the compiling processes compile what the warm-up then only loads.

    They use recorded calls; the real warm-up ran once per session (conftest: every
    solver, both builds with several threads, the energy, self-contact, moving bodies).
    Every recorded signature must be one the real calls compiled.
    """
    calls = kernel_calls(parallel=numba.get_num_threads() > 1, energy=True, self_contact=True,
                         bodies=True, tangent_strain=True)
    names = {d.py_func.__name__ for d, _ in calls}
    assert {'eq7_level', 'strain_limit', 'contact', 'conjugate_gradient', 'energy',
            'self_contact', 'body_contact', 'tangent_strain_limit'} <= names
    without = {d.py_func.__name__ for d, _ in kernel_calls(
        parallel=numba.get_num_threads() > 1, energy=True)}
    assert not {'self_contact', 'body_contact', 'tangent_strain_limit'} & without
    for dispatcher, signature in calls:
        assert signature in dispatcher.overloads, (dispatcher.py_func.__name__, signature)


def test_cache_directory_is_keyed_on_every_kernel_source(tmp_path):
    copy = tmp_path / 'kernels'
    shutil.copytree(jit.SOURCES, copy, ignore=shutil.ignore_patterns('__pycache__'))
    assert jit.source_digest(str(copy)) == jit.source_digest()
    helper = copy / 'springs.py'            # a helper other modules' kernels call
    helper.write_text(helper.read_text().replace('stretch >= 0.0', 'stretch > 0.0'))
    assert jit.source_digest(str(copy)) != jit.source_digest()
    assert jit.CACHE_DIR.endswith(jit.PREFIX + jit.source_digest())
    # numba caches the kernels there (not beside each source file)
    for name in ('eq7_level', 'strain_limit', 'force_row'):
        dispatcher = getattr(kernels.SERIAL, name, None) or getattr(
            kernels.springs, name)
        path = dispatcher._cache._cache_path
        assert os.path.commonpath([path, jit.CACHE_DIR]) == jit.CACHE_DIR, path


def test_parallel_builds_are_other_functions_with_their_own_cache_entries():
    for name in ('eq7_level', 'strain_limit', 'strain_stats', 'system_apply'):
        serial, parallel = getattr(kernels.SERIAL, name), getattr(kernels.PARALLEL, name)
        assert serial is not parallel
        assert parallel.targetoptions.get('parallel') and not serial.targetoptions.get(
            'parallel')
        assert (serial._cache._cache_file._index_name
                != parallel._cache._cache_file._index_name)
    assert kernels.PARALLEL.prolong is kernels.SERIAL.prolong
    assert kernels.builds(9, 9, 2) is kernels.SERIAL           # one chunk: no threads
    assert kernels.builds(257, 257, 1) is kernels.SERIAL
    assert kernels.builds(257, 257, 2) is kernels.PARALLEL
    for rows, cols in ((45, 45), (46, 45), (32, 64), (31, 66), (2048, 1)):
        # the pure-Python choice agrees with the kernels' own chunking
        assert (kernels.builds(rows, cols, 2) is kernels.PARALLEL) == (
            kernels.chunk_count(rows, cols) > 1), (rows, cols)


def test_a_cache_directory_pruned_during_the_warm_up_is_survived(monkeypatch, tmp_path):
    """
    Another process started on edited kernel sources prunes this one's cache directory.

    The warm-up then cannot write its stamp: the kernels are compiled all the same, no
    error (it raised FileNotFoundError, seen when the test suite ran while a kernel was
    edited), and nothing says they are cached.
    """
    from hcloth_ros.core import warmup
    gone = tmp_path / 'pruned'
    monkeypatch.setattr(jit, 'CACHE_DIR', str(gone))
    seconds = warmup.warm_up(solvers=['explicit'], parallel=False, energy=False, processes=1)
    assert seconds >= 0.0
    assert not gone.exists()
    assert not warmup.kernels_cached(solvers=['explicit'], parallel=False, energy=False)


def _reference_counts(options):
    """Count numba's reference-counting calls in self-contact's edge test compiled so."""
    import numpy as np
    self_contact = importlib.import_module('hcloth_ros.core.kernels.self_contact')
    edge_side = numba.njit(**{**options, 'cache': False})(self_contact._edge_side.py_func)
    x0 = np.zeros((3, 4))
    x0[0] = (0.0, 1.0, 0.0, 1.0)
    x1 = x0.copy()
    x1[2] = (0.1, 0.1, -0.1, -0.1)
    edge_side(x0, x1, 0, 1, 2, 3, 0.01, 2, np.zeros(3), True)
    code = edge_side.inspect_llvm(edge_side.signatures[0])
    return code.count('call void @NRT_incref') + code.count('call void @NRT_decref')


def test_kernels_that_borrow_arrays_count_no_references():
    """
    Check that kernels compiled with BORROW make no reference-counting call, JIT's do.

    The edge test takes three arrays and calls helpers whose error status leaves LLVM
    paths it cannot prove balanced: compiled with JIT, each call increments and
    decrements the arrays' counts (29 % of self-contact's time on the sliding folded
    drop); with BORROW, none. The innermost kernels of self-contact and of the moving
    bodies are compiled so.
    """
    # (the modules, not the kernels of the same names the package exports)
    self_contact = importlib.import_module('hcloth_ros.core.kernels.self_contact')
    bodies = importlib.import_module('hcloth_ros.core.kernels.bodies')
    assert _reference_counts(jit.JIT) > 0
    assert _reference_counts(jit.BORROW) == 0
    for kernel in (self_contact._edge_side, self_contact._edge_against,
                   self_contact._points_against, self_contact._pair_side,
                   self_contact._near_blocks, self_contact._resolve, bodies._respond):
        assert kernel.targetoptions.get('_nrt') is False, kernel.py_func.__name__
