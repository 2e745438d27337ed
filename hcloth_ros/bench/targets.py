"""
The accurate solver against its targets: swing and grasp at 33 x 33 and 65 x 65, rest shape.

    python -m hcloth_ros.bench.targets [--sizes 33,65] [--repeats 3] [--json PATH]
                                       [--option NAME=VALUE ...]

For each finest size (level 0 9 x 9, so 3 and 4 levels) and scenario it computes the
converged reference (:mod:`.reference`: symplectic Euler at a small step, about 4 min at
65 x 65), then runs at dt = 1/60 s on one numba thread:

* ``multigrid``: the default (BDF2 and multigrid-CG up to level 1, 17 x 17; eq. 7 above);
* ``multigrid full``: the same solved on the finest level;
* ``hierarchical``: the paper's method as the node ran it before (the comparison).

It prints the RMS vertex distance to the reference over the whole 2 s and over the first
second (the swing is chaotic after about 1.6 s), the largest strain and wall seconds per
simulated second (the best of ``--repeats`` runs: the machine is shared). ``--option``
adds a solver option to both ``multigrid`` rows (e.g. ``newton_tolerance_steps=moved``;
YAML values). Last, the rest
shape: the cloth hung from its top corners settles (air drag 1 N s/m^3) and its drop below
the pins is compared with the energy minimum of :mod:`.equilibrium`.
"""

import argparse
import json
import os
import sys

from hcloth_ros.bench import equilibrium, errors
from hcloth_ros.bench.plan import Method
from hcloth_ros.bench.reference import reference
from hcloth_ros.bench.scenarios import simulate


DT = 1.0 / 60.0
LEVELS = {17: 2, 33: 3, 65: 4}
METHODS = (('multigrid', 'multigrid', {}),
           ('multigrid full', 'multigrid', {'accurate_level': None}),
           ('hierarchical', 'hierarchical', {}))


def methods(extra=None):
    """:data:`METHODS` with the solver options ``extra`` added to the multigrid ones."""
    return [(label, solver, dict(options, **(extra or {})) if solver == 'multigrid'
             else options) for label, solver, options in METHODS]


def accuracy(sizes, repeats, progress=print, extra=None):
    """Rows of the target table: one per size, scenario and method (see :func:`methods`)."""
    rows = []
    for n in sizes:
        for scenario in ('swing', 'grasp'):
            progress(f'reference {scenario} {n} x {n} ...')
            ref, check = reference(scenario, n, 2.0)
            for label, solver, options in methods(extra):
                runs = [simulate(scenario, solver, n, LEVELS[n], DT, 2.0, options=options)
                        for _ in range(repeats)]
                run = runs[0]
                row = {'n': n, 'scenario': scenario, 'method': label,
                       'rms': errors.position_rms(run, ref),
                       'rms_first_second': errors.first_second_rms(run, ref),
                       'max_strain': run.max_strain, 'failed': run.failed,
                       'wall_per_sim_second': min(r.wall_per_sim_second for r in runs),
                       'reference_self_check': check}
                rows.append(row)
                progress(f'{n:3d} {scenario:5s} {label:15s} RMS {row["rms"]:.4f} m, first '
                         f'second {row["rms_first_second"]:.4f} m, strain '
                         f'{row["max_strain"]:.3f}, {row["wall_per_sim_second"]:.3f} s per '
                         f'simulated s {run.failed}')
    return rows


def rest_shape(n=33, seconds=3.0):
    """Drop of the hung cloth (m): the multigrid solver's, the energy minimum's."""
    points, _, failed = equilibrium.settle(Method('multigrid', 'multigrid', (), LEVELS[n]), n,
                                           seconds, DT)
    if failed:
        raise RuntimeError(f'the hanging cloth blew up: {failed}')
    got = equilibrium.drop(points)
    _, expected = equilibrium.reference(n)
    return {'n': n, 'drop': got, 'energy_minimum_drop': expected,
            'relative_error': got / expected - 1.0}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', default='33,65')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--json', metavar='PATH')
    parser.add_argument('--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a multigrid solver option (YAML value), repeatable')
    args = parser.parse_args(argv)
    from hcloth_ros.params import assignments
    extra = assignments(args.option)
    import numba
    numba.set_num_threads(1)
    print(f'targets at dt = 1/60 s, 1 numba thread, load average {os.getloadavg()[0]:.2f} '
          f'on {os.cpu_count()} CPUs', flush=True)
    sizes = [int(s) for s in args.sizes.split(',') if s]
    results = {'accuracy': accuracy(sizes, args.repeats,
                                    lambda text: print(text, flush=True), extra)}
    rest = results['rest_shape'] = rest_shape()
    print(f'rest shape, {rest["n"]} x {rest["n"]} hung from two corners: drop '
          f'{rest["drop"]:.5f} m, energy minimum {rest["energy_minimum_drop"]:.5f} m '
          f'({100 * rest["relative_error"]:+.3f} %)', flush=True)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
