"""
The ``multigrid`` solver: BDF2 with a few Newton iterations, multigrid-preconditioned CG.

The hierarchy as a solver, not only a filter. Up to its ``accurate_level`` the cloth steps
by an implicit integrator of the full spring model (:mod:`.kernels.bdf2`): BDF2 by default
(second order, A-stable; the first step after a start, a reset or a jump of the state is
backward Euler), or backward Euler throughout. Each step runs a fixed number of Newton
iterations from an extrapolated first guess; each Newton iteration solves its linear
system by CG preconditioned with a V-cycle over the levels ``0 .. accurate_level``
(:mod:`.kernels.multigrid`), also for a fixed most number of iterations. A step whose
residual is still large after them (a cloth that contact and self-contact pushed about)
takes more, up to a cap (with ``newton_tolerance_steps='moved'`` only a step that starts
from a state something moved after the last solve, or whose residual the fixed count
leaves above ``RUNAWAY`` tolerances); the levels the V-cycle needs are the model's own.

Levels finer than ``accurate_level`` follow the paper's Table 1 (constraint C and
eq. 7) from the accurate level's velocity change: large-scale motion from the accurate
solve, detail from the cheap refinement. Levels coarser than it are the accurate level's
own points (injection), so every level is a complete mesh after every step.

Material damping (air drag, spring damping) comes from the model; with none, how fast a
cloth settles is BDF2's own small numerical damping.
"""

from hcloth_ros.core import buffers
from hcloth_ros.core.kernels.layout import FREE
from hcloth_ros.core.kernels.multigrid import DENSE_MAX_POINTS
from hcloth_ros.core.model import ClothBuilder
from hcloth_ros.core.solvers import HierarchicalSolver
import numpy as np

INTEGRATORS = ('bdf2', 'backward_euler')
# which steps iterate Newton to its tolerance: all, or those starting from a state something
# moved after the last solve (see MultigridSolver._from_own_solve)
TOLERANCE_STEPS = ('all', 'moved')
# with 'moved', a step that starts from its own last solve still iterates while its
# residual is above this many tolerances: a stiff cloth at a large step (k = 1e5 N/m, 17 x
# 17 at 1/30 s) left 43 at the median after the fixed count and blew up; a free swing
# leaves at most 6-7 (tools/newton_residuals.py)
RUNAWAY = 10.0


def _grids_below(model, smallest=3):
    """
    Coarser grids below level 0 for the V-cycle, coarse to fine (model levels of their own).

    Level 0 is halved while both sides stay odd and above ``smallest`` points, with level
    0's springs and contraction and the same cloth: a V-cycle that ends on a grid of a few
    points corrects the cloth's largest motions almost exactly, at almost no cost (on the
    33 x 33 swing a V-cycle ending at 9 x 9 after 8 block-Jacobi sweeps left the first
    second 3x further from the reference than one ending at 3 x 3).
    """
    lv0 = model.level(0)
    rows, cols, count = lv0.rows, lv0.cols, 0
    while (rows - 1) % 2 == 0 and (cols - 1) % 2 == 0 and min(rows, cols) > smallest:
        rows, cols, count = (rows - 1) // 2 + 1, (cols - 1) // 2 + 1, count + 1
    if count == 0:
        return []
    return list(ClothBuilder(
        width=model.width, height=model.height, resolution=(cols, rows), level_count=count,
        total_mass=model.total_mass, k_struct=lv0.stiffness[0], k_shear=lv0.stiffness[4],
        k_bend=lv0.stiffness[8], contraction=[lv0.contraction] * count).finalize().levels)


def _norm(a):
    """Euclidean norm of an array's entries (not np.vdot: BLAS threads, see core.blas)."""
    return float(np.sqrt(np.sum(np.square(a))))


# m/s^2: the unit of weight the Newton tolerance is given in (whatever the model's gravity)
STANDARD_GRAVITY = 9.81
# the residual a step may leave, in units of the momentum the weight gives over the step
NEWTON_TOLERANCE = 0.3


def _inserted(level):
    """1.0 at the points a level inserts, 0.0 at those it inherits (even row and column)."""
    mask = np.ones((level.rows, level.cols))
    mask[::2, ::2] = 0.0
    return mask


class _Hierarchy:
    """Flat buffers of the V-cycle's grids (below level 0, then levels ``0 .. top``)."""

    def __init__(self, model, top):
        levels = _grids_below(model) + [model.level(k) for k in range(top + 1)]
        sizes = [lv.rows * lv.cols for lv in levels]
        self.shapes = np.array([[lv.rows, lv.cols] for lv in levels], dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = int(self.offsets[-1])
        self.base_mass = np.concatenate([lv.mass.ravel() for lv in levels])
        self.air_drag = self.base_mass * (model.air_drag * model.width * model.height
                                          / model.total_mass)
        self.rest = np.array([lv.rest for lv in levels])
        self.stiffness = np.array([lv.stiffness for lv in levels])
        self.contraction = np.array([lv.contraction for lv in levels])
        self.free = np.ones(total)
        self.positions = buffers.zeros(3 * total)
        self.mass = buffers.zeros(total)
        self.coef_uu = buffers.zeros(6 * total)
        self.coef_iso = buffers.zeros(6 * total)
        self.directions = buffers.zeros(18 * total)
        self.block_inverse = buffers.zeros(6 * total)
        self.mg = [buffers.zeros(3 * total) for _ in range(3)]
        rows, cols = self.shapes[-1]
        self.top_air_drag = self.air_drag[self.offsets[-2]:].reshape(rows, cols)
        coarsest = sizes[0] if sizes[0] <= DENSE_MAX_POINTS else 0
        self.factor = buffers.zeros((3 * coarsest, 3 * coarsest))
        shape = (3, levels[-1].rows, levels[-1].cols)
        # finest-level vectors: v+, held targets, -R, the correction, CG's r, z, p, Ap
        (self.v, self.target, self.rhs, self.correction, self.r, self.z, self.p,
         self.ap) = (buffers.zeros(shape) for _ in range(8))

    def set_holds(self, kind):
        """Mark the top level's free points (the coarser grids follow by injection)."""
        np.copyto(self.free[self.offsets[-2]:], (kind == FREE).ravel())


class MultigridSolver(HierarchicalSolver):
    """
    BDF2 (or backward Euler) up to ``accurate_level``, Newton with multigrid-PCG.

    :param integrator: ``'bdf2'`` or ``'backward_euler'``.
    :param accurate_level: the finest level solved by the integrator, clipped to the
        model's finest (None: the finest); finer ones are refined by eq. 7. The default,
        level 1 (17 x 17 on a 9 x 9 level 0), was the most accurate per second of the
        choices measured on the benchmark's 33 x 33 and 65 x 65 swing: its few CG
        iterations converge further on a small grid, and the motion it misses is the fine
        detail eq. 7 adds.
    :param newton_iterations: Newton iterations every step takes.
    :param cg_iterations: most PCG iterations per Newton iteration.
    :param max_newton_iterations: most Newton iterations a step may take: after
        ``newton_iterations``, more while the residual (2-norm) is above
        ``newton_tolerance`` times the momentum the cloth's weight (at 9.81 m/s^2) gives
        it over the step (``beta M g``). Taken as ``newton_iterations`` when smaller: a
        fixed count. In contact the fixed three left residuals of 10-60 weights on the
        fold demo's scene, springs at 30-50 % after every solve, and the cloth tore
        (1795 top-layer points below the bottom layer; issue 10's note); a free swing
        leaves 0.03-0.2 at the median.
    :param newton_tolerance: see ``max_newton_iterations``.
    :param newton_tolerance_steps: which steps iterate to the tolerance: ``'all'``; or
        ``'moved'``, those that start from a state something moved after the last solve
        (contact, self-contact, an edit, a start: :meth:`_from_own_solve`), so that a
        free cloth takes the fixed count at a nearly fixed cost, for real time on large
        meshes; a step from the last solve still iterates while its residual is above
        ``RUNAWAY`` tolerances (stiff cloth at large steps: k = 1e5 N/m at 1/30 s blew up
        without). ``'all'`` buys accuracy where a fine level is solved and the cloth moves
        fast (65 x 65 grasp solved there 0.081 -> 0.055 m RMS), at up to twice the cost
        (see the README's "In contact: Newton to a tolerance"). The node's parameter
        defaults to ``'moved'``: a steady tick at 60 Hz on 257 x 257 solved to 65 x 65.
    :param extra_cg_iterations: most PCG iterations of each Newton iteration beyond
        ``newton_iterations`` (the fold converged with 10, not with 2).
    :param cg_rtol: PCG stops earlier once the residual fell by this factor.
    :param smoothing_sweeps: block-Jacobi sweeps before and after each coarse correction.
    :param coarse_sweeps: block-Jacobi sweeps on level 0.
    :param omega: damping of the block-Jacobi sweeps.
    :param strain_limit: strain limiting on the refinement levels (eq. 7 alone lets their
        springs stretch: 30 % within half a second of the swing).
    :param solved_strain_limit: strain limiting on the solved level, off by default: its
        springs hold the cloth on their own.
    :param options: those of :class:`~hcloth_ros.core.solvers.HierarchicalSolver`.

    Refinement levels run eq. 7 as :class:`HierarchicalSolver` does (backward-Euler form,
    from ``x_n``, ``v_n`` with step h), then their inserted points move by the prolonged
    difference between the coarser level's displacement and ``h`` times its new velocity:
    BDF2 moves a point by ``x^ - x_n + beta v+``, not ``h v+``, and without this an inserted
    point drifts from the points it lies between (``h^2 g / 3`` a step under gravity,
    100 % strain within 2 s). Eq. 7 from the BDF2 anchor instead blows up: one Jacobi
    step is not the converged solve BDF2's stability needs.
    """

    name = 'multigrid'
    refine_drift = True

    def __init__(self, model, integrator='bdf2', accurate_level=1, newton_iterations=3,
                 cg_iterations=2, cg_rtol=1e-3, smoothing_sweeps=1, coarse_sweeps=4,
                 omega=0.67, solved_strain_limit=None,
                 max_newton_iterations=12, newton_tolerance=NEWTON_TOLERANCE,
                 newton_tolerance_steps='all', extra_cg_iterations=10, **options):
        super().__init__(model, **options)
        if solved_strain_limit is not None and not 0.0 < solved_strain_limit < 10.0:
            raise ValueError('solved_strain_limit must be in (0, 10) or None, '
                             f'got {solved_strain_limit}')
        self.solved_strain_limit = solved_strain_limit
        if integrator not in INTEGRATORS:
            raise ValueError(f'integrator must be one of {INTEGRATORS}, got {integrator!r}')
        top = model.level_count - 1
        if accurate_level is not None and int(accurate_level) < 0:
            raise ValueError(f'accurate_level must be >= 0 or None, got {accurate_level}')
        self.accurate_level = top if accurate_level is None else min(int(accurate_level), top)
        for name, value, high in (('newton_iterations', newton_iterations, 100),
                                  ('cg_iterations', cg_iterations, 10000),
                                  ('smoothing_sweeps', smoothing_sweeps, 100),
                                  ('coarse_sweeps', coarse_sweeps, 1000)):
            if not 1 <= int(value) <= high:
                raise ValueError(f'{name} must be in 1..{high}, got {value}')
        if not 0.0 < cg_rtol < 1.0:
            raise ValueError(f'cg_rtol must be in (0, 1), got {cg_rtol}')
        if not 0.0 < omega <= 1.0:
            raise ValueError(f'omega must be in (0, 1], got {omega}')
        for name, value, high in (('max_newton_iterations', max_newton_iterations, 100),
                                  ('extra_cg_iterations', extra_cg_iterations, 10000)):
            if not 1 <= int(value) <= high:
                raise ValueError(f'{name} must be in 1..{high}, got {value}')
        if not (np.isfinite(newton_tolerance) and newton_tolerance > 0.0):
            raise ValueError(f'newton_tolerance must be positive, got {newton_tolerance}')
        if newton_tolerance_steps not in TOLERANCE_STEPS:
            raise ValueError(f'newton_tolerance_steps must be one of {TOLERANCE_STEPS}, '
                             f'got {newton_tolerance_steps!r}')
        self.newton_tolerance_steps = newton_tolerance_steps
        self.integrator = integrator
        self.newton_iterations = int(newton_iterations)
        self.cg_iterations = int(cg_iterations)
        self.cg_rtol = float(cg_rtol)
        self.smoothing_sweeps = int(smoothing_sweeps)
        self.coarse_sweeps = int(coarse_sweeps)
        self.omega = float(omega)
        self.max_newton_iterations = max(int(max_newton_iterations), self.newton_iterations)
        self.extra_cg_iterations = int(extra_cg_iterations)
        self.newton_tolerance = float(newton_tolerance)
        self._hierarchies = {}
        # per level: the anchor of the step, and BDF2's history (the state before the
        # last step and after it)
        self._x_hat = [buffers.zeros_like(q) for q in self._q]
        self._v_hat = [buffers.zeros_like(q) for q in self._q]
        self._previous = [(buffers.zeros_like(q), buffers.zeros_like(q)) for q in self._q]
        self._current = [(buffers.zeros_like(q), buffers.zeros_like(q)) for q in self._q]
        self._history_key = None
        self._history = False
        self._beta = None
        # per solved level: its state as the last Newton solve left it (before contact and
        # the other passes after the solve), and whether that solve is the last one made
        self._solved = {}
        self._solved_key = None
        # per refinement level: 1.0 at its inserted points (the drift correction and the
        # momentum matching move only those) and their total mass
        self._inserted = [None] + [_inserted(lv) for lv in model.levels[1:]]
        self._inserted_total = [None] + [float(np.sum(lv.mass * mask)) for lv, mask in
                                         zip(model.levels[1:], self._inserted[1:])]

    def _strain_limit(self, refinement):
        return self.strain_limit if refinement else self.solved_strain_limit

    def solved_level(self):
        """Return the level the integrator solves: the accurate one, or the finest."""
        return min(self.accurate_level, self.finest_level)

    def solves(self, k):
        return k == self.solved_level()

    def _hierarchy(self, top):
        if top not in self._hierarchies:
            self._hierarchies[top] = _Hierarchy(self.model, top)
        return self._hierarchies[top]

    def checkpoint(self):
        """
        Return what :meth:`restore` needs: self-contact's memory and BDF2's history.

        With the history back, a step taken again from the same state is the same step
        (``core.recovery`` takes a refused step whole after all when its smallest retries
        stretched the cloth further: without it that step ran as backward Euler, the
        history being of the smaller steps undone).
        """
        top = self.solved_level()
        return (super().checkpoint(), top, self._history_key,
                tuple(a.copy() for a in self._previous[top] + self._current[top]))

    def restore(self, checkpoint):
        """Undo the steps committed since ``checkpoint`` (state: the caller's)."""
        base, top, key, arrays = checkpoint
        super().restore(base)
        self._history_key = key
        for kept, now in zip(arrays, self._previous[top] + self._current[top]):
            np.copyto(now, kept)

    def _has_history(self, state, key, top):
        """Whether the last accepted step of this solver led to ``state`` (BDF2 may go on)."""
        return (self._history_key == key and np.array_equal(self._current[top][0], state.q[top])
                and np.array_equal(self._current[top][1], state.qd[top]))

    def step(self, state, control, dt):
        """Advance ``state`` by ``dt`` (see :meth:`Solver.step`); keeps BDF2's history."""
        h = float(dt)
        top = self.solved_level()
        # which points are held: a pin or grasp that lets go (or takes hold) changes the
        # forces the history was made under (BDF2 through a released pin put the centre of
        # mass up to 80 % off g in the first steps)
        held = (control.holds(top).kind != FREE).tobytes()
        key = (h, self.integrator, self.finest_level, state.time, held)
        self._history = self.integrator == 'bdf2' and self._has_history(state, key, top)
        if not self._history:
            # a start, a reset, another step size, an edited state or other holds:
            # backward Euler
            self._history_key = None
            np.copyto(self._current[top][0], state.q[top])
            np.copyto(self._current[top][1], state.qd[top])
        self._beta = 2.0 * h / 3.0 if self._history else h
        report = super().step(state, control, dt)
        if report.ok:
            self._previous[top], self._current[top] = self._current[top], self._previous[top]
            if self._corrections_leave_history(top):
                # the state before this step moves with what the passes after the solve
                # changed, so that BDF2 sees only the solve's motion (the strain limiting
                # workspace, free at the step's end, holds each change)
                x_before, v_before = self._previous[top]
                solved_q, solved_qd = self._solved[top]
                change = self._scratch[top]
                np.subtract(state.q[top], solved_q, out=change)
                x_before += change
                np.subtract(state.qd[top], solved_qd, out=change)
                v_before += change
            np.copyto(self._current[top][0], state.q[top])
            np.copyto(self._current[top][1], state.qd[top])
            self._history_key = (h, self.integrator, self.finest_level, state.time, held)
        report.newton_iterations = report.extra.get('newton_iterations', 0)
        report.cg_iterations = report.extra.get('cg_iterations', 0)
        report.converged = report.extra.get('converged', True)
        return report

    def _corrections_leave_history(self, top):
        """
        Whether BDF2's history leaves out what moved the solved level after its solve.

        Contact, strain limiting and self-contact correct the solve's result. Kept in the
        history, a correction is motion to BDF2: the anchor ``(4 x_n - x_{n-1}) / 3`` and
        its velocity carry a third of it into the next step, and the next correction
        answers that. With the 65 x 65 finest level solved, a folded cloth lying on the
        ground after the release gained kinetic energy (0.09 to 52 mJ in one second) and
        rolled its fold open in 3 of 8 runs of the fold demo's scene (crease 50.5 cm from
        the middle); left out, 8 of 8 held (crease 1.2-3.1 cm), and a cloth pushed with
        nothing else acting on it stays put. The passes after the solve then scale
        velocities by ``h``, not ``beta``: with ``beta`` a cloth on a tray accelerated
        under Coulomb friction at 1.5 times ``mu g``; with ``h``, at ``mu g`` exactly
        (``test_bodies.py``, ``multigrid-finest``). A cloth lying still still sinks by its
        weight's ``g h^2`` in each solve, and is pushed back after it.

        Only where the solved level is the finest simulated one. Below a refined finest
        level, the finest level's contact reaches the solve through the history alone:
        left out, the 17 x 17 solve of a cloth draped over a table pulled its table-top
        points by the edges 13-15 mm a step into the table (the corner's reaction, which
        acts on no coarse point, missing), and the 129 x 129 finest
        springs at the edge stretched to 0.19 against 0.105 (the limit's 1.5 times is
        0.15). (``doc/accurate_solver_log.md``.)
        """
        return top == self.finest_level

    def _prescribe(self, k, state, holds, h):
        """
        Held points' change; on the solved level from the step's anchor, over beta.

        Levels below the solved one are not integrated (they are its points): nothing.
        """
        top = self.solved_level()
        if k == top:
            kit = self.kernels(k)
            kit.anchor(state.q[k], state.qd[k], self._previous[k][0], self._previous[k][1],
                       self._history, holds.kind, self._x_hat[k], self._v_hat[k])
            kit.prescribe(self._x_hat[k], self._v_hat[k], holds.kind, holds.drive_index,
                          holds.drive_target, self._beta, self._presc[k])
        elif k > top:
            super()._prescribe(k, state, holds, h)

    def _integrate(self, k, state, holds, h):
        top = self.solved_level()
        if k > top:
            self._refine(k, state, holds, h)
        elif k == top:
            self._solve(top, state, holds, h, self._beta)
            scale = h if self._corrections_leave_history(top) else self._beta
            self._post(top, state, holds, scale, False)
            kit = self.kernels(top)
            for level in range(top - 1, -1, -1):    # the coarser levels are its points
                for arrays in (self._q, self._qd, self._dv):
                    kit.inject(arrays[level + 1], arrays[level])

    def _refine(self, k, state, holds, h):
        """
        Table 1 on level k (constraint C, eq. 7), the displacement correction, then post.

        Momentum is matched only with nothing held and no obstacle touched this step: an
        obstacle's push changes the momentum (on the table scene, matching after contact
        moved 104 finest points back into the table; before contact, the finest springs
        ran away).
        """
        # with what the coarser level moved beyond h v+ prolonged onto the free inserted
        # points (refine_drift; held points are where their holds put them)
        self._eq7(k, state, holds, h)
        self._post(k, state, holds, h, True)
        if not holds.kind.any() and not self._touched:
            self._match_momentum(k, state, h)

    def _match_momentum(self, k, state, h):
        """
        Give level k the momentum change of level k-1 (nothing held, so none is lost).

        Eq. 7 and strain limiting do not conserve momentum; a uniform velocity change of
        the inserted points (and ``h`` times it in position) restores it, so the finest
        level's centre of mass falls as the solved level's does.
        """
        fine_mass, coarse_mass = self.model.level(k).mass, self.model.level(k - 1).mass
        target = (np.einsum('drc,rc->d', self._qd[k - 1], coarse_mass)
                  - np.einsum('drc,rc->d', state.qd[k - 1], coarse_mass)
                  + np.einsum('drc,rc->d', state.qd[k], fine_mass))
        shift = ((target - np.einsum('drc,rc->d', self._qd[k], fine_mass))
                 / self._inserted_total[k])
        change = shift[:, None, None] * self._inserted[k]
        self._qd[k] += change
        self._dv[k] += change
        self._q[k] += h * change

    def _conserve_momentum(self, hier, top, kind, beta):
        """
        Zero the Newton residual's sum by a uniform velocity change (nothing held).

        The springs' forces cancel in pairs, so the residual's sum is the error of the
        cloth's momentum alone; the inexact linear solves leave some (0.15 % of g on the
        33 x 33 cloth released mid-swing). One more residual evaluation removes it.
        """
        lv, g = self.model.level(top), self.model.gravity
        x_hat, v_hat = self._x_hat[top], self._v_hat[top]
        drag = hier.top_air_drag
        self.kernels(top).newton_residual(
            x_hat, v_hat, hier.v, hier.target, kind, beta, lv.mass, drag, lv.rest,
            lv.stiffness, lv.contraction, self.model.spring_damping, g,
            self._q[top], hier.rhs)
        shift = hier.rhs.sum(axis=(1, 2)) / (lv.mass.sum() + beta * drag.sum())
        hier.v += shift[:, None, None]

    def _from_own_solve(self, top, state):
        """
        Whether the step starts where the last solve of level ``top`` left it, untouched.

        Nothing moved it since: no contact, self-contact, strain limiting or finer level's
        wrap after that solve, no edit, reset or refused step. Such a start is as close to
        balance as the fixed Newton count leaves a free cloth; any other may be far from it.
        """
        if self._solved_key != top:
            return False
        q, qd = self._solved[top]
        return np.array_equal(q, state.q[top]) and np.array_equal(qd, state.qd[top])

    def _keep_solved(self, top):
        """
        Remember the solve's result of level ``top``.

        For :meth:`_from_own_solve`, and for BDF2's history where
        :meth:`_corrections_leave_history`: what moved the level after the solve.
        """
        if top not in self._solved:
            self._solved[top] = (buffers.zeros_like(self._q[top]),
                                 buffers.zeros_like(self._q[top]))
        np.copyto(self._solved[top][0], self._q[top])
        np.copyto(self._solved[top][1], self._qd[top])
        self._solved_key = top

    def _solve(self, top, state, holds, h, beta):
        """
        Take the implicit step of level ``top`` into ``_q``, ``_qd`` and ``_dv`` (``v+ - v_n``).

        ``newton_iterations`` Newton iterations, each one multigrid-PCG solve, then more
        while the residual is above tolerance (on the steps ``newton_tolerance_steps``
        names, see the class).
        """
        hier = self._hierarchy(top)
        kit, lv, g = self.kernels(top), self.model.level(top), self.model.gravity
        hier.set_holds(holds.kind)
        x_hat, v_hat, presc = self._x_hat[top], self._v_hat[top], self._presc[top]
        np.add(v_hat, presc, out=hier.target)       # on held points: x^ + beta v+
        hier.target *= beta
        hier.target += x_hat
        v, x_new = hier.v, self._q[top]
        kit.start_velocity(self._current[top][1], h, g, v_hat, presc, holds.kind, v)
        cg_total = 0
        # the residual left may be this much of the momentum the cloth's weight gives it
        # over the step
        tolerance = self.newton_tolerance * beta * self.model.total_mass * STANDARD_GRAVITY
        adaptive = self.max_newton_iterations > self.newton_iterations
        # the residual a step leaves (a start from the last solve, with 'moved': RUNAWAY
        # tolerances; see the class)
        limit = tolerance
        if self.newton_tolerance_steps == 'moved' and self._from_own_solve(top, state):
            limit = RUNAWAY * tolerance
        newton, converged = 0, True
        while adaptive or newton < self.newton_iterations:
            kit.newton_residual(x_hat, v_hat, v, hier.target, holds.kind, beta, lv.mass,
                                hier.top_air_drag, lv.rest, lv.stiffness, lv.contraction,
                                self.model.spring_damping, g, x_new, hier.rhs)
            cg_max = self.cg_iterations
            if newton >= self.newton_iterations:
                residual = _norm(hier.rhs)
                if newton == self.newton_iterations:    # in units of the tolerance
                    self._extra['fixed_count_residual'] = residual / tolerance
                converged = residual <= tolerance
                if residual <= limit or newton == self.max_newton_iterations:
                    break
                cg_max = self.extra_cg_iterations
            newton += 1
            # the matrix at every iteration: assembled once at the first guess (an option
            # before) Newton diverged on the first step of the swing and the grasp at 65 x 65
            # (the rest state's matrix has no transverse stiffness the stretched springs have)
            kit.assemble_hierarchy(x_new, hier.shapes, hier.offsets, hier.rest, hier.stiffness,
                                   hier.contraction, self.model.spring_damping, beta,
                                   hier.base_mass, hier.air_drag, hier.positions, hier.mass,
                                   hier.coef_uu, hier.coef_iso, hier.directions,
                                   hier.block_inverse, hier.free, hier.factor)
            iterations, _ = kit.multigrid_cg(
                hier.shapes, hier.offsets, hier.mass, hier.free, hier.coef_uu, hier.coef_iso,
                hier.directions, hier.block_inverse, hier.factor, hier.rhs, cg_max,
                self.cg_rtol, self.smoothing_sweeps, self.coarse_sweeps, self.omega,
                hier.mg[0], hier.mg[1], hier.mg[2], hier.r, hier.z, hier.p, hier.ap,
                hier.correction)
            cg_total += iterations
            v += hier.correction
        if not holds.kind.any():
            self._conserve_momentum(hier, top, holds.kind, beta)
        kit.new_positions(x_hat, v, hier.target, holds.kind, beta, x_new)
        np.copyto(self._qd[top], v)
        np.subtract(v, self._current[top][1], out=self._dv[top])     # v+ - v_n
        self._keep_solved(top)
        self._extra['cg_iterations'] = cg_total
        self._extra['newton_iterations'] = newton
        self._extra['converged'] = converged
