"""
The paper's figures, reproduced: Fig. 3/5, Fig. 6 and Fig. 4.

Fig. 3/5: hierarchical against single-level approximate and the coarse mesh alone;
Fig. 6: wrinkles from contraction resistance; Fig. 4: the 8192-point cloth in real time.
"""

import time

from hcloth_ros.bench.reference import reference_dt
from hcloth_ros.bench.scenarios import build_model, simulate
from hcloth_ros.core import ClothBuilder, Control, make_solver, Placement, State
from hcloth_ros.core.metrics import mean_curvature, wrinkliness
import numba
import numpy as np

SNAPSHOTS = (0.25, 0.5, 1.0, 2.0)


def fig3_runs(plan, progress):
    """
    Run the swinging cloth in each case of Fig. 3/5; return ``(n, runs)``.

    The cloth has 9 x 9 level 0 and ``plan.paper_levels`` levels. The cases, with the
    paper's literal gravity: (a) hierarchical, (b) the coarse mesh alone, (c) the fine
    mesh with single-level eq. 6; plus the hierarchy with exact gravity (``external``'s
    default) and the reference.
    """
    levels = plan.paper_levels
    n = 8 * 2 ** (levels - 1) + 1
    seconds = plan.paper_seconds
    cases = [
        ('(a) hierarchical, literal (paper)', 'hierarchical', n, levels,
         {'external': 'literal'}, 1 / 60),
        ('(b) coarse mesh alone, approx literal', 'approx', 9, 1, {'external': 'literal'},
         1 / 60),
        ('(c) fine mesh, approx literal (one level)', 'approx', n, 1,
         {'external': 'literal'}, 1 / 60),
        ('hierarchical, exact gravity', 'hierarchical', n, levels, {}, 1 / 60),
        ('reference (explicit, small step)', 'explicit', n, 1, {'strain_limit': None},
         reference_dt(n)),
    ]
    runs = {}
    for label, solver, size, lv, options, dt in cases:
        progress(f'paper fig. 3/5: {label}')
        runs[label] = simulate('swing', solver, size, lv, dt, seconds, options=options)
    return n, runs


def chart_fig3(n, runs, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    instants = [t for t in SNAPSHOTS if t <= max(r.times[-1] for r in runs.values()) + 1e-9]
    fig = plt.figure(figsize=(3.0 * len(instants) + 5.5, 2.3 * len(runs)))
    grid = fig.add_gridspec(len(runs), len(instants) + 2)
    for i, (label, run) in enumerate(runs.items()):
        side = int(round(np.sqrt(run.points.shape[1])))
        for j, t in enumerate(instants):
            ax = fig.add_subplot(grid[i, j])
            s = int(np.argmin(np.abs(run.times - t)))
            p = run.points[s].reshape(side, side, 3)
            # side view along x: every grid column as a polyline in (y, z)
            for c in range(0, side, max(1, side // 8)):
                ax.plot(p[:, c, 1], p[:, c, 2], color='tab:orange', lw=0.8)
            ax.set_xlim(-1.1, 1.1)
            ax.set_ylim(0.3, 1.6)
            ax.set_aspect('equal')
            ax.tick_params(labelsize=6)
            if i == 0:
                ax.set_title(f't = {t:g} s', fontsize=9)
            if j == 0:
                ax.set_ylabel(label, fontsize=7)
    half = max(1, len(runs) // 2)
    ax = fig.add_subplot(grid[:half, len(instants):])
    log = fig.add_subplot(grid[half:, len(instants):])
    for label, run in runs.items():
        style = {'lw': 2.5 if label.startswith('reference') else 1.4,
                 'color': 'k' if label.startswith('reference') else None}
        ax.plot(run.times, run.com[:, 2], label=label, **style)
        # the literal runs barely move: their drop only shows on a log scale
        log.plot(run.times[1:], 1.5 - run.com[1:, 2], **style)
    ax.set_ylabel('centre of mass height (m)')
    ax.set_title(f'fall curve, finest {n} x {n}, dt = 1/60 s', fontsize=9)
    ax.legend(fontsize=7)
    log.set_yscale('log')
    log.set_ylabel('centre of mass drop (m)')
    log.set_xlabel('time (s)')
    for a in (ax, log):
        a.grid(alpha=0.3, which='both')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def fig6_runs(plan, progress):
    """
    Run Fig. 6: contraction resistance all 1 against 0.5 on the coarse levels.

    The paper compares (1, 1, 1, 1) against (0.5, 0.5, 1, 1): ``hierarchical`` (exact
    gravity) on the swinging cloth.
    """
    levels = plan.paper_levels
    n = 8 * 2 ** (levels - 1) + 1
    stiff = [1.0] * levels
    soft = [0.5] * max(1, levels - 2) + [1.0] * min(2, levels - 1)
    out = {}
    for values in (stiff, soft):
        label = '(' + ', '.join(f'{v:g}' for v in values) + ')'
        progress(f'paper fig. 6: contraction {label}')
        run = simulate('swing', 'hierarchical', n, levels, 1 / 60, plan.paper_seconds,
                       contraction=values)
        model = build_model(n, levels, contraction=values)
        state = State.at_rest(model)
        state.q[-1][:] = run.points[-1].T.reshape(3, n, n)
        out[label] = {'run': run, 'wrinkle': wrinkliness(model, state, levels - 1),
                      'curvature': mean_curvature(model, state, levels - 1)}
    return n, out


def chart_fig6(n, results, path):
    """
    Draw the final cloths seen from the front, on one colour scale.

    Each face is coloured by the mean curvature ``|H|`` of its corner (the quantity the
    wrinkle measure averages).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize
    top = max(float(np.percentile(r['curvature'], 99)) for r in results.values())
    norm = Normalize(0.0, top)
    fig = plt.figure(figsize=(5.0 * len(results) + 1, 5.0))
    for i, (label, res) in enumerate(results.items()):
        ax = fig.add_subplot(1, len(results), i + 1, projection='3d')
        p = res['run'].points[-1].reshape(n, n, 3)
        h = np.pad(res['curvature'], 1, mode='edge')
        ax.plot_surface(p[:, :, 0], p[:, :, 1], p[:, :, 2], facecolors=plt.cm.magma(norm(h)),
                        linewidth=0, antialiased=False, shade=False)
        ax.view_init(elev=8, azim=-80)
        ax.set_title(f'contraction {label}\nwrinkle measure {res["wrinkle"]:.2f} 1/m',
                     fontsize=9)
        ax.set_box_aspect((1, 1, 1))
    fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap='magma'), ax=fig.axes,
                 shrink=0.7, label='mean curvature |H| (1/m)')
    fig.savefig(path, dpi=90)
    plt.close(fig)


def fig4_timing(progress, seconds=1.0, dt=1 / 60):
    """
    Time the median step of ``hierarchical`` on the grids nearest the paper's 8192 points.

    The two grids are 89 x 89 = 7921 and 65 x 129 = 8385 points; one and two threads.
    """
    rows = []
    for resolution, levels in (((12, 12), 4), ((9, 17), 4)):
        model = ClothBuilder(resolution=resolution, level_count=levels,
                             placement=Placement((-0.5, 0.0, 1.5), (1, 0, 0), (0, 1, 0))
                             ).finalize()
        top = model.level(levels - 1)
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            progress(f'paper fig. 4: {top.rows} x {top.cols}, {threads} thread(s)')
            numba.set_num_threads(threads)
            state, control = State.at_rest(model), Control(model)
            control.set_pins([0, model.level(0).cols - 1])
            solver = make_solver('hierarchical', model)
            times = []
            for _ in range(int(round(seconds / dt))):
                start = time.perf_counter()
                solver.step(state, control, dt)
                times.append(time.perf_counter() - start)
            rows.append({'points': top.rows * top.cols, 'grid': f'{top.cols} x {top.rows}',
                         'threads': threads, 'median_ms': 1e3 * float(np.median(times)),
                         'p90_ms': 1e3 * float(np.percentile(times, 90)),
                         'real_time_factor': dt / float(np.median(times))})
    numba.set_num_threads(1)
    return rows
