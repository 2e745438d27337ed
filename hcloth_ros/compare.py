"""Motion of each method on the hanging cloth against a converged reference.

    python -m hcloth_ros.compare [--levels 3] [--seconds 2] [--out out/compare]

The scene is ``config/hanging.yaml`` with a smaller hierarchy by default (33 x 33 finest)
so that the reference is cheap: symplectic Euler at a step far below its stability limit,
checked by halving the step (the printed "reference self-check" must be small against the
errors it is used to judge). Every method then runs at dt = 1/60 s on the same finest mesh;
the table gives the centre-of-mass height error against the reference (RMS over the run
and at the end), the RMS vertex position error, and the largest strain seen, and
``com.png`` plots the centre-of-mass height of each. This is where the effect of strain
limiting and of the two gravity treatments on motion is measured.
"""

import argparse
import os
import time

import numpy as np

from hcloth_ros import params
from hcloth_ros.core import make_solver, warm_up
from hcloth_ros.core.metrics import centre_of_mass, strain


def run(values, solver_name, dt, seconds, samples, **options):
    """Simulate and sample the finest level ``samples`` times; returns a dict of series."""
    model, _, state, control = params.build_all(values)
    solver = make_solver(solver_name, model, **options)
    steps = int(round(seconds / dt))
    every = steps // samples
    k = model.level_count - 1
    com, points, worst, failed = [], [], 0.0, ''
    start = time.perf_counter()
    for i in range(1, steps + 1):
        report = solver.step(state, control, dt)
        if not report.ok:
            failed = f'refused at t = {state.time:.3f} s: {report.reason}'
            break
        worst = max(worst, strain(model, state, k)[0])
        if i % every == 0:
            com.append(centre_of_mass(model, state, k)[2])
            points.append(state.points(k))
    wall = time.perf_counter() - start
    return dict(com=np.array(com), points=np.array(points), max_strain=worst,
                failed=failed, wall=wall)


def compare(values, seconds, samples, ref_dt, progress=print):
    configs = [
        ('hierarchical, exact, strain limit 10 %', 'hierarchical',
         dict(external='exact', strain_limit=0.1)),
        ('hierarchical, exact, no strain limit', 'hierarchical',
         dict(external='exact', strain_limit=None)),
        ('hierarchical, literal (paper)', 'hierarchical',
         dict(external='literal', strain_limit=None)),
        ('approx, exact, strain limit 10 %', 'approx', dict(external='exact', strain_limit=0.1)),
        ('approx, literal (paper)', 'approx', dict(external='literal', strain_limit=None)),
        ('implicit (backward Euler, tol 1e-6 m)', 'implicit',
         dict(tolerance=1e-6, strain_limit=None)),
    ]
    progress(f'reference: explicit at dt = {ref_dt:.2e} s and {ref_dt / 2:.2e} s ...')
    ref = run(values, 'explicit', ref_dt, seconds, samples, strain_limit=None)
    half = run(values, 'explicit', ref_dt / 2, seconds, samples, strain_limit=None)
    if ref['failed'] or half['failed']:
        raise RuntimeError(f'reference failed: {ref["failed"] or half["failed"]}')
    check = float(np.sqrt(np.mean((ref['points'] - half['points']) ** 2)))
    rows = [dict(name='reference self-check (dt halved)', com_rms=float(
        np.sqrt(np.mean((ref['com'] - half['com']) ** 2))), com_end=float(
        abs(ref['com'][-1] - half['com'][-1])), pos_rms=check,
        max_strain=half['max_strain'], wall=half['wall'], failed='')]
    series = {'reference': ref['com']}
    for name, solver, options in configs:
        progress(f'{name} ...')
        out = run(values, solver, 1 / 60, seconds, samples, **options)
        n = len(out['com'])
        rows.append(dict(
            name=name, failed=out['failed'], max_strain=out['max_strain'], wall=out['wall'],
            com_rms=float(np.sqrt(np.mean((out['com'] - ref['com'][:n]) ** 2))) if n else np.nan,
            com_end=float(abs(out['com'][-1] - ref['com'][n - 1])) if n else np.nan,
            pos_rms=float(np.sqrt(np.mean((out['points'] - ref['points'][:n]) ** 2)))
            if n else np.nan))
        series[name] = out['com']
    return rows, series


def plot(series, seconds, path, title):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, com in series.items():
        t = np.arange(1, len(com) + 1) * seconds / len(series['reference'])
        ax.plot(t, com, lw=2.5 if name == 'reference' else 1.3,
                color='k' if name == 'reference' else None, label=name)
    ax.set_xlabel('simulated time (s)')
    ax.set_ylabel('centre of mass height (m)')
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    from hcloth_ros.demo import config_path
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scene', default=config_path('hanging.yaml'))
    parser.add_argument('--levels', type=int, default=3)
    parser.add_argument('--seconds', type=float, default=2.0)
    parser.add_argument('--samples', type=int, default=60)
    parser.add_argument('--ref-dt', type=float, default=5e-5)
    parser.add_argument('--out', default='out/compare')
    args = parser.parse_args(argv)
    values = params.resolve({**params.load_file(args.scene), 'cloth.levels': args.levels})
    warm_up()
    rows, series = compare(values, args.seconds, args.samples, args.ref_dt)
    os.makedirs(args.out, exist_ok=True)
    n0 = values['cloth.resolution'][0]
    side = 2 ** (args.levels - 1) * (n0 - 1) + 1
    title = (f'hanging cloth, finest {side}x{side}, {args.seconds:g} s; methods at dt = 1/60 s, '
             f'reference explicit at {args.ref_dt:.0e} s')
    plot(series, args.seconds, os.path.join(args.out, 'com.png'), title)
    print(f'\n{title}')
    print(f'{"method":42s} {"com rms (m)":>11s} {"com end (m)":>11s} {"pos rms (m)":>11s} '
          f'{"max strain":>10s} {"wall (s)":>8s}')
    for r in rows:
        print(f'{r["name"]:42s} {r["com_rms"]:11.4f} {r["com_end"]:11.4f} {r["pos_rms"]:11.4f} '
              f'{r["max_strain"]:10.3f} {r["wall"]:8.2f}  {r["failed"]}')
    print(f'wrote {os.path.join(args.out, "com.png")}')


if __name__ == '__main__':
    main()
