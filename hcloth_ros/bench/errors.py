"""
How far a run is from its reference, and whether it stayed sane.

All take :class:`~hcloth_ros.bench.scenarios.Run` objects sampled at the same instants; a
run that stopped early is compared over the samples it has.
"""

import numpy as np

STRAIN_BOUND = 0.25     # over-stretched beyond 25 %: no woven fabric stretches that far
# blown up if energy rises this many m g size above its start: a cloth stretched by the
# strain bound everywhere holds about 30 m g size, a blow-up soon holds orders more
ENERGY_RUNAWAY = 100.0
STABLE, BLOWN_UP, OVERSTRETCHED = 'stable', 'blown up', 'over-stretched'


def _common(run, ref):
    n = min(len(run.times), len(ref.times))
    if n == 0 or not np.allclose(run.times[:n], ref.times[:n], atol=1e-9):
        raise ValueError('runs are not sampled at the same instants')
    return n


def position_rms(run, ref):
    """RMS over samples and vertices of the distance to the reference vertex (m)."""
    n = _common(run, ref)
    d = np.linalg.norm(run.points[:n].astype(float) - ref.points[:n], axis=2)
    return float(np.sqrt(np.mean(d ** 2)))


def first_second_rms(run, ref):
    """
    RMS vertex distance over the samples of the first second (m).

    The swing is chaotic after about 1.6 s (the reference itself moves 0.012-0.018 m when
    its step is halved), so the first second is the part of a run that measures the method.
    """
    n = min(_common(run, ref), int(np.sum(ref.times <= 1.0 + 1e-9)))
    d = np.linalg.norm(run.points[:n].astype(float) - ref.points[:n], axis=2)
    return float(np.sqrt(np.mean(d ** 2)))


def com_rms(run, ref):
    """RMS over samples of the centre-of-mass distance to the reference's (m)."""
    n = _common(run, ref)
    return float(np.sqrt(np.mean(np.sum((run.com[:n] - ref.com[:n]) ** 2, axis=1))))


def excess_energy_loss_rate(run, ref):
    """
    Energy the run lost beyond what the reference lost, per simulated second (W).

    The artificial damping of a method: 0 for a perfect integrator, positive when it
    dissipates (implicit Euler, filtered steps), negative when it gains energy.
    """
    n = _common(run, ref)
    t = run.times[n - 1]
    if t <= 0:
        return float('nan')
    return float(((ref.energy[n - 1] - ref.energy[0]) - (run.energy[n - 1] - run.energy[0])) / t)


def compare(run, ref):
    """Every error figure of ``run`` against ``ref`` in one dict."""
    return {'position_rms': position_rms(run, ref),
            'position_rms_first_second': first_second_rms(run, ref),
            'com_rms': com_rms(run, ref),
            'energy_loss_rate': excess_energy_loss_rate(run, ref),
            'max_strain': float(run.max_strain)}


def classify(run, mass=0.2, size=1.0, g=9.81, strain_bound=STRAIN_BOUND):
    """
    Classify a run as ``STABLE``, ``BLOWN_UP`` or ``OVERSTRETCHED``.

    ``BLOWN_UP``: a refused step, non-finite values or energy running away;
    ``OVERSTRETCHED``: largest strain beyond ``strain_bound``.

    Energy may rise by the work of a driven grasp and by strain limiting (a cloth held at
    10 % stretch stores about 10 J), so the runaway threshold is generous:
    ``ENERGY_RUNAWAY`` times ``m g size`` (about 200 J for the benchmark cloth).
    """
    if run.failed or not np.all(np.isfinite(run.energy)) or not np.all(np.isfinite(run.points)):
        return BLOWN_UP
    if np.max(run.energy - run.energy[0]) > ENERGY_RUNAWAY * mass * g * size:
        return BLOWN_UP
    if run.max_strain > strain_bound:
        return OVERSTRETCHED
    return STABLE


def pareto_front(costs, errors):
    """Return the indices of the runs no other run beats on both cost and error, by cost."""
    order = np.lexsort((np.asarray(errors), np.asarray(costs)))
    front, best = [], np.inf
    for i in order:
        if np.isfinite(errors[i]) and errors[i] < best:
            front.append(int(i))
            best = errors[i]
    return front
