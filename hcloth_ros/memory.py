"""
What a scene will take in memory, from its parameters, before anything is allocated.

A scene inside every parameter's range can still need more memory than the machine has
(``cloth.resolution: [1025, 1025]`` with ``cloth.levels: 10`` is about 3.7e11 points):
the node then allocated until the kernel killed it, taking memory from everything else.
:func:`refusal` says why a scene is refused before it is built.

The bytes per point are peaks measured with ``tracemalloc`` over building the scene and
three steps, every level simulated (``multigrid`` solved on every level, its most
expensive setting), divided by the points of all levels, rounded up a little from the
figures at 22,325 points; larger scenes take slightly less a point, smaller ones more,
which ``BASE`` covers (README, "Memory"). ``BASE`` is the node's resident memory with a
small scene (interpreter, numba's compiled kernels, rclpy): 215 MB measured.
"""

# peak bytes per point (all levels), per solver; self-contact adds its grid and pairs
# (the measured peaks at 22,325 points, 129 x 129 finest, rounded up by 2-5 %)
BYTES_PER_POINT = {'multigrid': 1050, 'hierarchical': 380, 'implicit': 520,
                   'explicit': 380, 'approx': 380}
# (2026-12-02: 264-390 B more a point with self-contact than without, the most under
# multigrid, now that the kernel's scratch arrays, about 260 B a finest point, are kept
# with its cache instead of made inside each call, where tracemalloc did not see them;
# 189-279 on 2026-11-29, when the estimate added 290)
SELF_CONTACT_BYTES = 400
# multigrid keeps its solved level's last solve (positions and velocities, 48 bytes a point
# of that level; counted on every point): for newton_tolerance_steps: moved and for BDF2's
# history (MultigridSolver._corrections_leave_history)
SOLVE_COPY_BYTES = 48
BASE = 215e6
MB = 1e6


def level_sizes(resolution, levels):
    """Return ``(rows, cols)`` of every level: each doubles the intervals of the last."""
    rows, cols = (int(n) for n in resolution)
    return [((rows - 1) * 2 ** k + 1, (cols - 1) * 2 ** k + 1) for k in range(int(levels))]


def estimate(values):
    """
    Return ``(bytes, points)``: the memory a scene of resolved ``values`` needs at most.

    ``values`` maps the scene parameter names (:mod:`hcloth_ros.params`) to values.
    """
    points = sum(r * c for r, c in level_sizes(values['cloth.resolution'],
                                               values['cloth.levels']))
    per_point = BYTES_PER_POINT[values['solver.name']]
    if float(values['self_contact.thickness']) > 0:
        per_point += SELF_CONTACT_BYTES
    if values['solver.name'] == 'multigrid':
        per_point += SOLVE_COPY_BYTES
    return BASE + per_point * points, points


def available():
    """Return the free memory Linux reports, ``MemAvailable`` in bytes; None if unknown."""
    try:
        with open('/proc/meminfo') as f:
            for line in f:
                if line.startswith('MemAvailable:'):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def refusal(values, budget_mb):
    """
    Why the scene of ``values`` must not be built, or None.

    Refused above ``budget_mb`` (the node's ``memory_budget_mb``) and above what the
    machine has available now.
    """
    need, points = estimate(values)
    levels = int(values['cloth.levels'])
    finest = level_sizes(values['cloth.resolution'], levels)[-1]
    what = (f'the scene needs about {need / MB:,.0f} MB ({points:,} points over {levels} '
            f'levels, finest {finest[0]} x {finest[1]})')
    if need > budget_mb * MB:
        return (f'{what}, more than memory_budget_mb {budget_mb:g}: lower cloth.levels or '
                'cloth.resolution, or raise memory_budget_mb')
    free = available()
    if free is not None and need > free:
        return f'{what}, more than the {free / MB:,.0f} MB this machine has available now'
    return None
