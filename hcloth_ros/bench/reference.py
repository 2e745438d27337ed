"""
Converged references: what every method is judged against.

Free fall has a closed form. The other scenarios use symplectic Euler (``explicit``, no
strain limiting: the plain spring model) on the finest mesh at a step well below its
stability limit, run twice, at dt and dt / 2. The RMS vertex distance between the two is
the reference's own uncertainty (``self_check``): errors of the methods below it are not
resolved, and the charts draw it.
"""

from hcloth_ros.bench import errors
from hcloth_ros.bench.scenarios import build_model, closed_form_free_fall, SAMPLE_EVERY, simulate
from hcloth_ros.core.metrics import explicit_step_bound
import numpy as np


def reference_dt(n, k=1000.0, fraction=0.25):
    """Return the largest ``SAMPLE_EVERY / 2^m`` below ``fraction`` of the explicit step bound."""
    bound = explicit_step_bound(build_model(n, 1, k), 0)
    dt = SAMPLE_EVERY
    while dt > fraction * bound:
        dt /= 2
    return dt


def reference(scenario, n, duration, k=1000.0):
    """``(run, self_check)``: the reference run and its RMS change when dt is halved (m)."""
    if scenario == 'free_fall':
        return closed_form_free_fall(n, duration), 0.0
    dt = reference_dt(n, k)
    run = simulate(scenario, 'explicit', n, 1, dt, duration, k, {'strain_limit': None})
    half = simulate(scenario, 'explicit', n, 1, dt / 2, duration, k, {'strain_limit': None})
    if run.failed or half.failed:
        raise RuntimeError(f'{scenario} reference at n = {n} failed: {run.failed or half.failed}')
    # the finer of the two is the reference; its error is at most about the difference
    return half, errors.position_rms(run, half)


def convergence_order(scenario, n, duration, dt, k=1000.0):
    """
    Observed order of symplectic Euler at dt.

    The order is log2 of the ratio of successive differences (runs at dt, dt/2, dt/4).
    First order gives about 1.
    """
    runs = [simulate(scenario, 'explicit', n, 1, dt / 2 ** i, duration, k,
                     {'strain_limit': None}) for i in range(3)]
    d1 = errors.position_rms(runs[0], runs[1])
    d2 = errors.position_rms(runs[1], runs[2])
    return float(np.log2(d1 / d2)), d1, d2
