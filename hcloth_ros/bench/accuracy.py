"""Speed against accuracy: every method, step and mesh against a converged reference."""

from hcloth_ros.bench import errors
from hcloth_ros.bench.plan import accuracy_methods
from hcloth_ros.bench.reference import reference, reference_dt
from hcloth_ros.bench.scenarios import SAMPLE_EVERY, simulate
import numpy as np


def explicit_dts(n):
    """Symplectic Euler's ladder: from 1/30 s down to twice the reference step."""
    dts, dt, smallest = [], SAMPLE_EVERY, 2 * reference_dt(n) * 0.999
    while dt >= smallest:
        dts.append(dt)
        dt /= 2
    return tuple(dts)


def jobs(plan):
    """``(scenario, n, method, dt)`` of every run, so progress can show a total."""
    out = []
    for scenario in plan.scenarios:
        for n in plan.sizes:
            for m in accuracy_methods(plan, n):
                if n > m.max_n:
                    continue
                dts = explicit_dts(n) if m.solver == 'explicit' else (m.dts or plan.dts)
                out.extend((scenario, n, m, dt) for dt in dts)
    return out


def sweep(plan, progress):
    """
    Run every job; ``progress(text)`` is called before each.

    Returns ``(rows, refs)``: one dict per run and the reference self-check per
    ``(scenario, n)``.
    """
    rows, refs = [], {}
    for scenario, n, m, dt in jobs(plan):
        key = (scenario, n)
        if key not in refs:
            progress(f'reference {scenario} n={n}')
            refs[key] = reference(scenario, n, plan.duration)
        ref, check = refs[key]
        progress(f'{scenario} n={n} {m.label} dt=1/{1 / dt:.0f}')
        run = simulate(scenario, m.solver, n, m.levels, dt, plan.duration, options=m.kwargs)
        row = {'scenario': scenario, 'n': n, 'method': m.label, 'solver': m.solver,
               'levels': m.levels, 'dt': dt, 'wall_per_sim_second': run.wall_per_sim_second,
               'status': errors.classify(run), 'failed': run.failed,
               'reference_self_check': check, 'reference_dt': ref.dt}
        if run.failed:
            row.update(position_rms=np.nan, position_rms_first_second=np.nan,
                       com_rms=np.nan, energy_loss_rate=np.nan,
                       max_strain=run.max_strain)
        else:
            row.update(errors.compare(run, ref))
        rows.append(row)
    return rows, {f'{s} n={n}': c for (s, n), (_, c) in refs.items()}


def _style(label):
    """Colour by solver family, dashes for the literal gravity treatment."""
    family = label.split()[0]
    colours = {'explicit': ['black'], 'approx': ['tab:blue'],
               'hierarchical': ['tab:orange', 'tab:red', 'tab:brown', 'tab:pink'],
               'implicit': ['tab:green', 'olive', 'tab:cyan'],
               'multigrid': ['tab:purple', 'indigo', 'orchid']}[family]
    index = 0
    if family == 'hierarchical':
        index = int(label.split('L')[-1]) - 2
    elif family == 'implicit':
        index = {'0.01': 0, '0.0001': 1}.get(label.split()[2], 2)
    elif family == 'multigrid':
        index = 1 if 'solved finest' in label else 2 if 'backward Euler' in label else 0
    return {'color': colours[min(index, len(colours) - 1)],
            'ls': '--' if 'literal' in label else '-', 'marker': 'o', 'ms': 4}


def chart(rows, self_checks, plan, path, metric='position_rms',
          ylabel='RMS vertex error (m)'):
    """
    Draw one panel per scenario and size: error against wall time per simulated second.

    Each panel has a line per method through its time steps (a cross marks a run that
    over-stretched or blew up before the end), the Pareto front of the runs that stayed
    sane, the reference's own uncertainty and the real-time line.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    scenarios, sizes = plan.scenarios, plan.sizes
    fig, axes = plt.subplots(len(scenarios), len(sizes), squeeze=False,
                             figsize=(6.5 * len(sizes), 4.2 * len(scenarios)))
    for i, scenario in enumerate(scenarios):
        for j, n in enumerate(sizes):
            ax = axes[i][j]
            # NaN (a run that stopped) is None once read back from results.json
            sel = [r for r in rows if r['scenario'] == scenario and r['n'] == n
                   and r[metric] is not None and np.isfinite(r[metric]) and r[metric] > 0]
            for label in dict.fromkeys(r['method'] for r in sel):
                mine = sorted((r for r in sel if r['method'] == label),
                              key=lambda r: r['wall_per_sim_second'])
                style = _style(label)
                ax.plot([r['wall_per_sim_second'] for r in mine], [r[metric] for r in mine],
                        label=label, **{**style, 'marker': None})
                for r in mine:      # a cross where the run over-stretched or blew up
                    ok = r['status'] == errors.STABLE
                    ax.plot(r['wall_per_sim_second'], r[metric], ls='none',
                            marker='o' if ok else 'x', ms=4 if ok else 6, color=style['color'])
            good = [r for r in sel if r['status'] == errors.STABLE]
            if good:
                # only runs that stayed sane can be worth their cost
                cost = np.array([r['wall_per_sim_second'] for r in good])
                err = np.array([r[metric] for r in good])
                front = errors.pareto_front(cost, err)
                ax.step(cost[front], err[front], where='post', color='grey', lw=6,
                        alpha=0.25, label='Pareto front')
            check = self_checks.get(f'{scenario} n={n}', 0.0)
            if metric == 'position_rms' and check > 0:
                ax.axhline(check, color='grey', ls=':', label='reference uncertainty')
            ax.axvline(1.0, color='k', lw=0.8, ls='-.', label='real time')
            ax.set_xscale('log')
            ax.set_yscale('log')
            ax.set_title(f'{scenario.replace("_", " ")}, finest {n} x {n}', fontsize=10)
            ax.set_xlabel('wall seconds per simulated second (1 thread)')
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3, which='both')
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc='lower center', ncol=4, fontsize=8)
    fig.tight_layout(rect=(0, 0.04 + 0.012 * (len(labels) // 4), 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)
