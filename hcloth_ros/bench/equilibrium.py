"""
The static equilibrium of a hanging cloth, computed without any solver of the engine.

A cloth at rest under gravity sits at a minimum of its potential energy

    E(x) = sum over springs 1/2 k_s (|x_j - x_i| - L_s)^2 - sum over points m_i g . x_i

(``k_s`` times the contraction resistance for a compressed spring), with its held points
fixed. :func:`minimise` finds it by L-BFGS with a backtracking line search, in plain numpy
from the formula: the reference a dynamic solver's rest shape is checked against (a
dynamic solver at rest satisfies ``f(x) = 0``, the same stationarity).

:func:`hang` is the benchmark's scenario: the benchmark cloth hung vertically from its top
corners at its rest shape, as the dynamic solvers start it.
"""

from hcloth_ros.core import ClothBuilder, Control, Placement, State
from hcloth_ros.core.kernels.layout import STENCIL_DC, STENCIL_DR
import numpy as np


def _pairs(rows, cols, s):
    """Flat index pairs ``(i, j)`` of the springs of stencil direction s (even s)."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing='ij')
    rn, cn = r + STENCIL_DR[s], c + STENCIL_DC[s]
    ok = (rn >= 0) & (rn < rows) & (cn >= 0) & (cn < cols)
    return (r * cols + c)[ok], (rn * cols + cn)[ok]


def energy_and_gradient(level, gravity, x):
    """Return ``E(x)`` (J) and its gradient (N) for positions ``x`` ``(n, 3)`` of one level."""
    e = -np.sum(level.mass.ravel()[:, None] * gravity[None, :] * x)
    grad = -level.mass.ravel()[:, None] * gravity[None, :]
    grad = np.broadcast_to(grad, x.shape).copy()
    for s in range(0, len(level.rest), 2):     # each spring once
        i, j = _pairs(level.rows, level.cols, s)
        d = x[j] - x[i]
        length = np.linalg.norm(d, axis=1)
        stretch = length - level.rest[s]
        k = np.where(stretch >= 0, level.stiffness[s], level.stiffness[s] * level.contraction)
        e += 0.5 * np.sum(k * stretch ** 2)
        f = (k * stretch / np.maximum(length, 1e-300))[:, None] * d   # pull on i toward j
        np.add.at(grad, i, -f)
        np.add.at(grad, j, f)
    return float(e), grad


def minimise(level, gravity, x0, held, tolerance=1e-9, max_iter=200000, memory=20):
    """
    Minimise the energy over the free points from ``x0`` ``(n, 3)``; ``held``: bool ``(n,)``.

    L-BFGS (Nocedal and Wright, algorithm 7.4) with Armijo backtracking; stops when the
    largest force on a free point is below ``tolerance`` times the cloth's weight. Returns
    ``(x, iterations, largest force in N)``.
    """
    free = ~held
    weight = float(np.sum(level.mass) * np.linalg.norm(gravity))
    x = x0.copy()
    e, g = energy_and_gradient(level, gravity, x)
    g[held] = 0.0
    s_list, y_list = [], []
    for it in range(1, max_iter + 1):
        if np.max(np.abs(g[free])) < tolerance * weight:
            return x, it - 1, float(np.max(np.abs(g[free])))
        q = g.ravel().copy()
        alphas = []
        for s, y in zip(reversed(s_list), reversed(y_list)):
            a = (s @ q) / (y @ s)
            alphas.append(a)
            q -= a * y
        if s_list:
            q *= (s_list[-1] @ y_list[-1]) / (y_list[-1] @ y_list[-1])
        for (s, y), a in zip(zip(s_list, y_list), reversed(alphas)):
            q += (a - (y @ q) / (y @ s)) * s
        direction = -q.reshape(x.shape)
        slope = float(np.sum(direction * g))
        if slope >= 0:                  # not a descent direction: restart from the gradient
            s_list, y_list = [], []
            direction, slope = -g, -float(np.sum(g * g))
        step = 1.0
        while True:
            x_new = x + step * direction
            e_new, g_new = energy_and_gradient(level, gravity, x_new)
            if e_new <= e + 1e-4 * step * slope or step < 1e-12:
                break
            step *= 0.5
        g_new[held] = 0.0
        s_vec, y_vec = (x_new - x).ravel(), (g_new - g).ravel()
        if y_vec @ s_vec > 1e-300:
            s_list.append(s_vec)
            y_list.append(y_vec)
            if len(s_list) > memory:
                s_list.pop(0)
                y_list.pop(0)
        x, e, g = x_new, e_new, g_new
    return x, max_iter, float(np.max(np.abs(g[free])))


def hanging_model(n, levels, k=1000.0, air_drag=0.0):
    """Build the benchmark cloth hung vertically: row 0 at the top (z = 1.5 m), rows going down."""
    n0, rem = divmod(n - 1, 2 ** (levels - 1))
    if rem:
        raise ValueError(f'a finest side of {n} points cannot be split into {levels} levels')
    return ClothBuilder(width=1.0, height=1.0, resolution=(n0 + 1, n0 + 1),
                        level_count=levels, total_mass=0.2, k_struct=k, k_shear=k,
                        k_bend=k / 10, air_drag=air_drag,
                        placement=Placement((-0.5, 0.0, 1.5), (1, 0, 0),
                                            (0, 0, -1))).finalize()


def hang(model):
    """Return ``(control, state)``: the cloth at its rest shape, top corners pinned."""
    control = Control(model)
    control.set_pins([0, model.level(0).cols - 1])
    return control, State.at_rest(model)


def drop(points):
    """Return how far the cloth hangs below its pins: top z minus lowest z (m), ``(n, 3)``."""
    return float(np.max(points[:, 2]) - np.min(points[:, 2]))


def reference(n, k=1000.0):
    """
    Return the equilibrium of the ``n x n`` hanging cloth: ``(points (n*n, 3), drop in m)``.

    Computed on one level of ``n`` points a side (the finest mesh of any hierarchy of it).
    """
    model = hanging_model(n, 1, k)
    control, state = hang(model)
    held = control.holds(0).kind.ravel() != 0
    x, _, _ = minimise(model.level(0), model.gravity, state.points(0), held)
    return x, drop(x)


# --- the benchmark section: every solver's rest shape against the energy minimum -------

SETTLE_SECONDS = 4.0
SETTLE_DT = 1.0 / 60.0
SETTLE_AIR_DRAG = 1.0   # N s/m^3; read by the multigrid solver only (the others damp anyway)


def methods(n):
    """List the methods whose rest shape is checked on an ``n x n`` cloth (plan.Method)."""
    from hcloth_ros.bench.plan import Method, multigrid_levels, multigrid_methods
    levels = multigrid_levels(n)
    return [*multigrid_methods(n),
            Method(f'hierarchical exact L{levels}, 10 % strain limit', 'hierarchical', (),
                   levels),
            Method(f'hierarchical exact L{levels}, no strain limit', 'hierarchical',
                   (('strain_limit', None),), levels),
            Method('implicit tol 1e-3 m', 'implicit',
                   (('tolerance', 1e-3), ('strain_limit', None)), max_n=33)]


def settle(method, n, seconds=SETTLE_SECONDS, dt=SETTLE_DT):
    """
    Hang the cloth at its rest shape and step it ``seconds``.

    Returns the finest points ``(n*n, 3)``, the largest speed at the end (m/s) and why the
    run stopped early ('' if it did not).
    """
    from hcloth_ros.core import make_solver
    model = hanging_model(n, method.levels, air_drag=SETTLE_AIR_DRAG)
    control, state = hang(model)
    solver = make_solver(method.solver, model, **method.kwargs)
    top = model.level_count - 1
    for _ in range(int(round(seconds / dt))):
        report = solver.step(state, control, dt)
        if not report.ok:
            return state.points(top), np.inf, report.reason
    speed = float(np.max(np.linalg.norm(state.qd[top].reshape(3, -1), axis=0)))
    return state.points(top), speed, ''


def rest_shapes(sizes, progress):
    """
    One row per size and method: its rest shape against the energy minimum.

    ``drop`` (m, top to lowest point), ``drop_error`` (relative to the minimum's),
    ``position_rms`` (m, every point against the minimum's) and ``end_speed`` (m/s, the
    largest at the end: near 0 when the cloth has settled).
    """
    rows = []
    for n in sizes:
        progress(f'equilibrium n={n}: energy minimum')
        x_min, drop_min = reference(n)
        for m in methods(n):
            if n > m.max_n:
                continue
            progress(f'equilibrium n={n}: {m.label}')
            x, speed, failed = settle(m, n)
            rows.append({'n': n, 'method': m.label, 'drop': drop(x), 'minimum_drop': drop_min,
                         'drop_error': drop(x) / drop_min - 1.0,
                         'position_rms': float(np.sqrt(np.mean(np.sum((x - x_min) ** 2,
                                                                      axis=1)))),
                         'end_speed': speed, 'failed': failed})
    return rows
