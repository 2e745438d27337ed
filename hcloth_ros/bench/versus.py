"""
Ours beside the peer simulators on the same swinging cloth, in the same run.

Each simulator runs at the largest step of one ladder at which it stays plausible: finite
and no structural edge stretched beyond ``STRAIN_BOUND``. Cost is wall seconds per
simulated second on one thread; the centre-of-mass trajectory is compared with our
converged reference of the spring model (height only: ``com_z_rms``) (the peers'
materials are fitted to it, not identical, so this measures plausibility, not equality).
"""

from hcloth_ros.bench import peers
from hcloth_ros.bench.reference import reference
from hcloth_ros.bench.scenarios import fits, level0_side, SAMPLE_EVERY, simulate
import numpy as np

STRAIN_BOUND = 0.2
LADDER = tuple(SAMPLE_EVERY / 2 ** i for i in range(8))     # 1/30 .. 1/3840 s


DEFAULT = 'hcloth multigrid'     # the row the others' costs are relative to


def _ours(n):
    # the default scene's 9 x 9 level 0 where the size allows it, else the most levels
    fitting = [lv for lv in range(1, 6) if fits(n, lv)]
    levels = next((lv for lv in fitting if level0_side(n, lv) == 9), max(fitting))
    return [(f'{DEFAULT} L{levels} (default)', 'multigrid', levels, {}),
            (f'hcloth hierarchical L{levels} (paper)', 'hierarchical', levels, {}),
            ('hcloth explicit', 'explicit', 1, {'strain_limit': None})]


def _largest_plausible_ours(solver, n, levels, options, duration, progress, label):
    for dt in LADDER:
        progress(f'peers n={n}: {label} dt=1/{1 / dt:.0f}')
        run = simulate('swing', solver, n, levels, dt, duration, options=options)
        if not run.failed and run.max_strain <= STRAIN_BOUND:
            return run, True
    return run, False


def compare(sizes, duration, progress, max_n=33):
    """
    Compare ours with the peers: one row per simulator and size.

    Sizes go up to ``max_n`` (PyBullet's stable step shrinks with the mesh); peers not
    installed are listed in ``missing``.
    """
    rows = []
    sizes = [n for n in sizes if n <= max_n]
    available = peers.available()
    for n in sizes:
        ref, _ = reference('swing', n, duration)
        for label, solver, levels, options in _ours(n):
            run, ok = _largest_plausible_ours(solver, n, levels, options, duration, progress,
                                              label)
            k = min(len(run.times), len(ref.times))
            rows.append({'simulator': label, 'version': '', 'n': n, 'dt': run.dt,
                         'plausible': ok, 'wall_per_sim_second': run.wall_per_sim_second,
                         'max_strain': run.max_strain, 'com_z_end': float(run.com[-1, 2]),
                         'com_z_rms': float(np.sqrt(np.mean(
                             (run.com[:k, 2] - ref.com[:k, 2]) ** 2))),
                         'material': 'springs 1000/1000/100 N/m, area-lumped masses',
                         'warnings': ''})
        for name in available:
            res = peers.largest_plausible_step(
                name, n, dts=LADDER, strain_bound=STRAIN_BOUND, duration=duration,
                on_run=lambda r: progress(f'peers n={n}: {r["peer"]} dt=1/{1 / r["dt"]:.0f}'))
            com = np.asarray(res['com_z'], float)
            k = min(len(com), len(ref.times))
            rows.append({'simulator': name, 'version': res['version'], 'n': n,
                         'dt': res['dt'], 'plausible': bool(res['plausible']),
                         'wall_per_sim_second': res['wall_per_sim_second'],
                         'max_strain': res['max_strain'], 'com_z_end': float(com[-1]),
                         'com_z_rms': float(np.sqrt(np.nanmean((com[:k] - ref.com[:k, 2]) ** 2))),
                         'material': res['material'],
                         'warnings': '; '.join(res.get('warnings', []))[:300]})
    for row in rows:
        ours = next(r for r in rows if r['n'] == row['n'] and r['simulator'].startswith(DEFAULT))
        row['cost_vs_hcloth_default'] = row['wall_per_sim_second'] / ours['wall_per_sim_second']
    missing = [name for name in peers.PEERS if name not in available]
    return rows, missing
