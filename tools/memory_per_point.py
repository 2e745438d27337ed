"""
Measure the memory a scene takes per point, per solver (the figures of hcloth_ros.memory).

    .venv/bin/python tools/memory_per_point.py [multigrid,hierarchical,...] [3,4,5,6]

For each solver, with and without self-contact (4 mm), builds the default scene (9 x 9
coarsest) with 3, 4, 5 and 6 levels, steps it 3 times with every level simulated
(``multigrid`` solved on every level) and prints the ``tracemalloc`` peak: held and peak
bytes, per point of all levels, and a straight-line fit of the peak against the points.
A first scene is built and stepped before measuring: the first one in a process also
loads the compiled kernels (about 17 MB).
"""

import gc
import sys
import tracemalloc

from hcloth_ros import params
import numpy as np

SOLVERS = ('multigrid', 'hierarchical', 'implicit', 'explicit', 'approx')


def scene(name, levels, thickness, base=9):
    """Return resolved parameter values of the default scene with these settings."""
    over = {'cloth.levels': levels, 'cloth.resolution': [base, base], 'solver.name': name,
            'self_contact.thickness': thickness}
    if name == 'multigrid':
        over['solver.accurate_level'] = 9      # solved on every level: its largest setting
    return params.resolve(over)


def measure(values, steps=3):
    """Return ``(points, held bytes, peak bytes)`` of building and stepping a scene."""
    gc.collect()
    tracemalloc.start()
    model, solver, state, control = params.build_all(values)
    for _ in range(steps):
        solver.step(state, control, 1 / 60)
    held, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return sum(lv.rows * lv.cols for lv in model.levels), held, peak


def main(argv):
    names = argv[0].split(',') if argv else SOLVERS
    levels = [int(v) for v in argv[1].split(',')] if len(argv) > 1 else (3, 4, 5, 6)
    measure(scene(names[0], 3, 0.0))        # load the kernels outside the figures
    for name in names:
        for thickness in (0.0, 0.004):
            rows = []
            for count in levels:
                points, held, peak = measure(scene(name, count, thickness))
                rows.append((points, peak))
                print(f'{name} self-contact {thickness * 1e3:g} mm, {count} levels, '
                      f'{points} points: held {held / 1e6:.1f} MB, peak {peak / 1e6:.1f} MB, '
                      f'{peak / points:.0f} B a point at the peak', flush=True)
            fit = np.polyfit(*np.array(rows, float).T, 1)
            print(f'  peak = {fit[0]:.0f} B a point + {fit[1] / 1e6:.2f} MB', flush=True)


if __name__ == '__main__':
    main(sys.argv[1:])
