"""
Where each method fails: stability maps and violent grasps.

Stability maps over time step and stiffness, and violent grasps (a grasp that jumps, one
that moves fast).
"""

from hcloth_ros.bench import errors
from hcloth_ros.bench.plan import Method, multigrid_methods, stability_methods
from hcloth_ros.bench.scenarios import build_model, simulate, VIOLENT, VIOLENT_TEXT
from hcloth_ros.core.metrics import explicit_step_limit
import numpy as np

CLASSES = (errors.STABLE, errors.OVERSTRETCHED, errors.BLOWN_UP)
COLOURS = {errors.STABLE: '#4caf50', errors.OVERSTRETCHED: '#ffb300',
           errors.BLOWN_UP: '#e53935'}


def map_jobs(plan):
    out = []
    for m in stability_methods(plan):
        for k in plan.stiffnesses:
            out.extend((m, k, dt) for dt in (m.dts or plan.stability_dts))
    return out


def stability_map(plan, progress):
    """
    Map every method on the swinging cloth: one row per (method, stiffness, dt).

    Also returns the theoretical explicit step limit per stiffness.
    """
    rows = []
    for m, k, dt in map_jobs(plan):
        progress(f'stability {m.label} k={k:g} dt=1/{1 / dt:.0f}')
        run = simulate('swing', m.solver, plan.stability_n, m.levels, dt,
                       plan.stability_duration, k=k, options=m.kwargs)
        rows.append({'method': m.label, 'k': k, 'dt': dt, 'status': errors.classify(run),
                     'max_strain': run.max_strain, 'failed': run.failed})
    limits = {k: explicit_step_limit(build_model(plan.stability_n, 1, k), 0)
              for k in plan.stiffnesses}
    return rows, limits


def explicit_boundary_check(rows, limits):
    """
    Check the explicit stability boundary against theory, per stiffness.

    Per stiffness: the largest explicit dt that did not blow up, the smallest that did,
    and the theoretical limit 2 / w_max; ``consistent`` when the limit lies between them
    (the measured boundary agrees with theory up to the ladder's factor of 2), None when
    the ladder does not reach both sides.
    """
    out = []
    for k, limit in limits.items():
        ex = [r for r in rows if r['method'] == 'explicit' and r['k'] == k]
        # over-stretched is still on the stable side: at k = 10 N/m the converged cloth
        # itself stretches beyond the bound, which says nothing about the integrator
        stable = [r['dt'] for r in ex if r['status'] != errors.BLOWN_UP]
        unstable = [r['dt'] for r in ex if r['status'] == errors.BLOWN_UP]
        lo = max(stable) if stable else 0.0
        hi = min(unstable) if unstable else np.inf
        # bracketed only when the ladder has runs on both sides of the boundary
        consistent = (bool(lo <= limit * 1.0001 and hi >= limit * 0.9999)
                      if stable and unstable else None)
        out.append({'k': k, 'theory': limit, 'largest_stable': lo, 'smallest_blown_up': hi,
                    'consistent': consistent})
    return out


def chart_map(rows, limits, plan, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
    methods = list(dict.fromkeys(r['method'] for r in rows))
    cols = min(4, len(methods))
    nrows = -(-len(methods) // cols)
    fig, axes = plt.subplots(nrows, cols, squeeze=False, figsize=(4.2 * cols, 3.6 * nrows),
                             sharex=True, sharey=True)
    ks = np.array(plan.stiffnesses)
    for ax, label in zip(axes.ravel(), methods):
        for r in rows:
            if r['method'] == label:
                ax.scatter(r['k'], r['dt'], s=160, marker='s', color=COLOURS[r['status']])
        if label == 'explicit':
            kk = np.geomspace(ks.min(), ks.max(), 50)
            # the limit scales as k^-1/2 for a fixed mesh and mass: interpolate in log
            lim = np.exp(np.interp(np.log(kk), np.log(ks), np.log([limits[k] for k in ks])))
            ax.plot(kk, lim, 'k--', label='theory: 2 / w_max')
            ax.legend(fontsize=7, loc='lower left')
        ax.set_xscale('log')
        ax.set_yscale('log')
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3, which='both')
    for ax in axes.ravel()[len(methods):]:
        ax.axis('off')
    for ax in axes[:, 0]:
        ax.set_ylabel('time step (s)')
    for ax in axes[-1, :]:
        ax.set_xlabel('spring stiffness k (N/m; bending k/10)')
    fig.legend([Patch(color=COLOURS[c]) for c in CLASSES],
               [c if c != errors.OVERSTRETCHED else f'over-stretched (> {errors.STRAIN_BOUND:.0%})'
                for c in CLASSES], loc='lower right', fontsize=9)
    fig.suptitle(f'swinging cloth, finest {plan.stability_n} x {plan.stability_n}, '
                 f'{plan.stability_duration:g} s', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --- violent control ---------------------------------------------------------------------
def violent_methods(n):
    levels = 3 if n >= 9 else 2
    return [Method('explicit', 'explicit', (('strain_limit', None),), dts=(1 / 1920,)),
            Method('approx exact', 'approx', dts=(1 / 60,)),
            Method('approx literal', 'approx', (('external', 'literal'),), dts=(1 / 60,)),
            Method(f'hierarchical exact L{levels}', 'hierarchical', (), levels,
                   dts=(1 / 60,)),
            Method(f'hierarchical literal L{levels}', 'hierarchical', (('external', 'literal'),),
                   levels, dts=(1 / 60,)),
            *(Method(m.label, m.solver, m.options, m.levels, dts=(1 / 60,))
              for m in multigrid_methods(n, backward_euler=False, levels=levels)),
            Method('implicit tol 1e-3 m', 'implicit',
                   (('tolerance', 1e-3), ('strain_limit', None)), dts=(1 / 60,))]


def violent_control(n, progress, duration=0.6):
    """
    Run each method against each violent grasp motion of the two corners.

    At dt = 1/60 s; explicit at 1/1920 s, a step it is stable at here. Each row holds the
    status and largest strain.
    """
    rows = []
    for motion in VIOLENT:
        for m in violent_methods(n):
            progress(f'violent {motion}: {m.label}')
            run = simulate(motion, m.solver, n, m.levels, m.dts[0], duration, options=m.kwargs)
            rows.append({'motion': motion, 'what': VIOLENT_TEXT[motion], 'method': m.label,
                         'dt': m.dts[0], 'status': errors.classify(run),
                         'max_strain': run.max_strain, 'failed': run.failed})
    return rows
