"""
Solvers: one ``step(state, control, dt)`` per method, selectable by name.

=================  ==================================================================
``explicit``       symplectic Euler on one level: the baseline that blows up at large
                   steps (stable below about ``2 / sqrt(max eigenvalue of M^-1 K)``).
``approx``         the paper's eq. 6 (two Jacobi sweeps of linearised backward Euler
                   with the diagonal Jacobian approximation) on one level.
``hierarchical``   the paper's Table 1: eq. 6 on level 0, then for each finer level
                   the constraint C (inherited points follow) and eq. 7 on new points.
``implicit``       backward Euler solved by Newton iterations with preconditioned CG on
                   the full spring Jacobian (Baraff and Witkin 1998): the reference.
=================  ==================================================================

External forces (gravity), option ``external``:

* ``'exact'`` (default): gravity is applied outside the filter, so a free point gains
  exactly ``h g`` per step and the centre of mass of a free cloth falls at exactly g; eq. 7
  removes ``h g`` from each neighbour's estimated change so it is counted once.
* ``'literal'``: gravity is part of ``f~`` and goes through the filter, as the paper
  writes it. A stiff or fine mesh then falls far slower than g (paper section III).

Every solver can limit strain (Provot 1995), pushes points out of the scene's obstacles,
and refuses a step that is non-finite or stretches a spring beyond ``blowup_strain``: the
state keeps its last good value and the report says why.
"""

from dataclasses import dataclass, field
import time

from hcloth_ros.core import buffers, kernels
from hcloth_ros.core.control import FREE
from hcloth_ros.core.scene import empty_scene, MARGIN
from hcloth_ros.core.self_contact import SelfContact
import numba
import numpy as np


EXTERNAL_MODES = ('exact', 'literal')
CONTACT_STRAIN = ('tangent', 'jacobi')
# each contact strain limiting's sweeps a round when not given: Jacobi sweeps are cheap and
# each moves a correction one point; tangent Gauss-Seidel stops once every spring is within
# the limit, and on the 129 x 129 table drop 100 left 0.171, 300 0.115
CONTACT_SWEEPS = {'jacobi': 10, 'tangent': 300}
# contact_relaxation's default: tangent strain limiting moves a spring's ends this many
# times its correction where they are free to move along it (kernels.contact_strain): on
# the 129 x 129 table drop 33.5 ms a step instead of 58.7, the contact bench's finger 13.1
# instead of 23.3, the largest strain the same or lower (doc/contact_log.md); 1.8 was faster
# still but let a cloth started in a box and a rising ball stretch more
TANGENT_RELAXATION = 1.5
NO_PLANES = np.zeros((0, 4))
NO_PLANES.setflags(write=False)     # as a scene's planes: one compiled signature
NO_SCENE = empty_scene()            # its arrays read-only too, as a scene's


@dataclass
class StepReport:
    """
    What one call to ``step`` did.

    ``ok`` is False when the step was refused (``reason`` says why) and the state was left
    as it was. ``max_strain``/``mean_strain`` are relative stretch of structural and shear
    springs on the finest simulated level after the step (0.1 = 10 %). A report of several
    steps taken in turn (:func:`merged`: a retry's smaller steps, a tick's substeps) is
    the last one's, but ``peak_strain`` is the largest ``max_strain`` after any of them,
    ``seconds`` and the iterations are their sums.
    """

    ok: bool
    reason: str = ''
    max_strain: float = 0.0
    mean_strain: float = 0.0
    levels: tuple = ()
    seconds: float = 0.0
    newton_iterations: int = 0
    cg_iterations: int = 0
    converged: bool = True
    extra: dict = field(default_factory=dict)
    # refused only because it stretched a spring past ``retry_strain`` (Solver): smaller
    # steps may not (core.recovery)
    stretched: bool = False
    # the largest max_strain of the accepted steps it stands for (None: this step's own)
    peak_strain: float = None

    def __post_init__(self):
        if self.peak_strain is None:
            self.peak_strain = self.max_strain if self.ok else 0.0


def merged(reports, seconds=None):
    """
    Return one report for ``reports``, steps taken in turn (the last may be a refusal).

    The last report, with ``peak_strain`` the largest of the accepted ones' (a strain
    reached between them and undone by the end is otherwise not seen), the iterations
    summed, ``converged`` only if all were, and ``seconds`` the given time (the tries a
    retry threw away included) or the reports' sum.
    """
    out = reports[-1]
    out.peak_strain = max((r.peak_strain for r in reports if r.ok), default=0.0)
    out.seconds = sum(r.seconds for r in reports) if seconds is None else seconds
    out.newton_iterations = sum(r.newton_iterations for r in reports)
    out.cg_iterations = sum(r.cg_iterations for r in reports)
    out.converged = all(r.converged for r in reports)
    return out


class Solver:
    """
    Shared machinery: buffers, holds, post-processing, blow-up check and commit.

    :param model: the :class:`ClothModel`.
    :param external: ``'exact'`` or ``'literal'`` (see the module docstring).
    :param strain_limit: largest stretch kept by strain limiting (0.1 = 10 %), or None to
        switch it off.
    :param strain_iterations: most Jacobi sweeps of strain limiting per step on a level that
        integrates all its points (level 0, or the one level of a single-level solver).
    :param strain_refine_iterations: most sweeps on a refinement level of the hierarchy. Its
        inherited points are fixed, so it only straightens what lies between them; it
        cannot undo a coarser level's stretch and would spend any budget trying.
    :param strain_tolerance: sweeps stop once no spring exceeds the limit by more than this
        (relative to the limit).
    :param blowup_strain: a step that leaves a spring stretched beyond this (relative) or
        any value non-finite is refused.
    :param retry_strain: a step in which self-contact found pairs and that stretches a
        spring of the finest simulated level beyond this (relative) from a start where
        none was is refused too, marked ``stretched``, so that
        :func:`~hcloth_ros.core.recovery.step_with_retries` takes it again in smaller steps
        (the 65 x 65 folded cloth's top layer thrown at 5 m/s onto the bottom one, pushed
        apart a pair at a time, ends its step at 0.60; retried as two half steps, 0.36
        after the first and 0.22 after the second: ``tools/thrown_fold.py``); None: off.
        Not retried: a start already stretched beyond it (two grippers pulling the cloth
        taut) and a step without self-contact pairs (a flood of far gripper poses took 15
        steps a tick). Grasps and moving bodies move evenly over
        the smaller steps (:meth:`Control.follow <hcloth_ros.core.control.Control.follow>`).
    :param builds: ``'serial'`` or ``'parallel'`` kernel builds on every level (or a kernel
        set with their names), or None: the parallel builds on levels large enough to
        split when numba runs several threads (see :mod:`hcloth_ros.core.kernels`).
    :param thickness: self-contact: the finest simulated level keeps its points this far
        (m) from its own triangles and no point crosses one during a step
        (:class:`~hcloth_ros.core.self_contact.SelfContact`); None switches it off.
    :param self_friction: friction coefficient between layers of the cloth.
    :param self_contact_iterations: most rounds of detection and response a check (then one
        more that moves points alone).
    :param self_contact_interval: check every n-th step.
    :param self_contact_edges: which edges are tested against edges: ``'auto'``,
        ``'creases'``, ``'sharp'`` or ``'all'``
        (:class:`~hcloth_ros.core.self_contact.SelfContact`).
    :param contact_rounds, contact_sweeps: on a step where a refinement level or the
        finest simulated level touched an obstacle, most rounds of strain limiting (this
        many sweeps, every point free) and contact on it, the coarser levels taking the
        finest state at the end of the step (:meth:`_wrap`); 0 rounds: none.
        ``contact_sweeps`` None: the strain limiting's own (:data:`CONTACT_SWEEPS`).
    :param contact_strain: the rounds' strain limiting: ``'tangent'`` (Gauss-Seidel, points
        lying on an obstacle moved along its surface, points a moving body presses into a
        plane left where it holds them: :mod:`~hcloth_ros.core.kernels.contact_strain`) or
        ``'jacobi'`` (the level's own, :mod:`~hcloth_ros.core.kernels.strain`: a spring
        across a table's edge stays at 0.77 strain on the 129 x 129 table drop where
        tangent keeps 0.115; under the contact bench's finger 0.60 against 0.11).
    :param contact_relaxation: tangent strain limiting moves the springs whose ends may move
        along them this many times their correction (in [1, 2); 1: plain Gauss-Seidel;
        :func:`~hcloth_ros.core.kernels.contact_strain.tangent_strain_limit`).
    :param contact_tethers: when tangent strain limiting's sweeps have not settled after a
        few, pull each point no farther from the nearest held point (a grip, a pin, a
        point a body presses into a plane) than the strain limit allows at their rest
        distance (:func:`~hcloth_ros.core.kernels.contact_strain._tether`).
    """

    name = ''

    def __init__(self, model, external='exact', strain_limit=0.1, strain_iterations=100,
                 strain_refine_iterations=4, strain_tolerance=0.005, blowup_strain=10.0,
                 retry_strain=None, builds=None, thickness=None, self_friction=0.3,
                 self_contact_iterations=8, self_contact_interval=1,
                 self_contact_edges='auto', contact_rounds=16,
                 contact_sweeps=None, contact_strain='tangent',
                 contact_relaxation=TANGENT_RELAXATION, contact_tethers=True):
        if external not in EXTERNAL_MODES:
            raise ValueError(f'external must be one of {EXTERNAL_MODES}, got {external!r}')
        if strain_limit is not None and not (0.0 < strain_limit < 10.0):
            raise ValueError(f'strain_limit must be in (0, 10) or None, got {strain_limit}')
        if contact_strain not in CONTACT_STRAIN:
            raise ValueError(f'contact_strain must be one of {CONTACT_STRAIN}, '
                             f'got {contact_strain!r}')
        if contact_sweeps is None:
            contact_sweeps = CONTACT_SWEEPS[contact_strain]
        for name, value in (('strain_iterations', strain_iterations),
                            ('strain_refine_iterations', strain_refine_iterations),
                            ('contact_sweeps', contact_sweeps)):
            if not (1 <= int(value) <= 10000):
                raise ValueError(f'{name} must be in 1..10000, got {value}')
        if not (0 <= int(contact_rounds) <= 10000):
            raise ValueError(f'contact_rounds must be in 0..10000, got {contact_rounds}')
        if not (1.0 <= contact_relaxation < 2.0):
            raise ValueError(f'contact_relaxation must be in [1, 2), got {contact_relaxation}')
        if not (0.0 < strain_tolerance < 1.0):
            raise ValueError(f'strain_tolerance must be in (0, 1), got {strain_tolerance}')
        if not (blowup_strain > 0):
            raise ValueError(f'blowup_strain must be positive, got {blowup_strain}')
        if retry_strain is not None and not (0.0 < retry_strain < blowup_strain):
            raise ValueError(f'retry_strain must be in (0, blowup_strain {blowup_strain:g}) '
                             f'or None, got {retry_strain}')
        self.self_contact = None if thickness is None else SelfContact(
            thickness, self_friction, self_contact_iterations, self_contact_interval,
            self_contact_edges)
        if isinstance(builds, str) and builds not in ('serial', 'parallel'):
            raise ValueError(f"builds must be 'serial', 'parallel' or None, got {builds!r}")
        self._builds = {'serial': kernels.SERIAL, 'parallel': kernels.PARALLEL}.get(
            builds, builds) if isinstance(builds, str) else builds
        self.model = model
        self._threads = None    # the kernel sets per level follow numba's thread count
        self._use_threads(numba.get_num_threads())
        self.literal = external == 'literal'
        self.external = external
        self.strain_limit = strain_limit
        self.strain_iterations = int(strain_iterations)
        self.strain_refine_iterations = int(strain_refine_iterations)
        self.strain_tolerance = float(strain_tolerance)
        self.contact_rounds = int(contact_rounds)
        self.contact_relaxation = float(contact_relaxation)
        self.contact_tethers = bool(contact_tethers)
        self.contact_sweeps = int(contact_sweeps)
        self.contact_strain = contact_strain
        self.blowup_strain = float(blowup_strain)
        self.retry_strain = None if retry_strain is None else float(retry_strain)
        shapes = [(3, lv.rows, lv.cols) for lv in model.levels]
        self._q = [buffers.zeros(s) for s in shapes]
        self._qd = [buffers.zeros(s) for s in shapes]
        self._dv = [buffers.zeros(s) for s in shapes]
        self._presc = [buffers.zeros(s) for s in shapes]
        self._scratch = [buffers.zeros(s) for s in shapes]
        self._a = [buffers.zeros(s) for s in shapes]
        self._integrated = [buffers.zeros(s) for s in shapes]
        # the finest level before the rounds that follow self-contact (see step)
        self._before_rounds = [buffers.zeros(s) for s in shapes]
        self._dinv = {}
        self._touched = False
        self._bodies, self._dt = np.zeros((0, 0)), 0.0     # set by each step
        self._inject = False
        self._finest_now = None

    # --- what subclasses provide ---------------------------------------------------------
    def levels(self):
        """Levels this solver integrates, coarse to fine."""
        raise NotImplementedError

    def _integrate(self, k, state, holds, h):
        """Write level k's new state into ``self._q/_qd/_dv[k]``."""
        raise NotImplementedError

    def set_finest_level(self, k, state, control):
        """Simulate levels up to k from the next step (no-op for one-level solvers)."""
        return self.levels()[-1]

    # --- shared --------------------------------------------------------------------------
    def kernels(self, k):
        """
        Return the kernel builds for level k.

        Parallel only with several numba threads and a level large enough to split
        (:func:`kernels.builds`), unless the solver was built with ``builds``.
        """
        return self._kits[k]

    def _use_threads(self, threads):
        """Pick each level's kernel set for ``threads`` numba threads (once per change)."""
        if threads != self._threads:
            self._threads = threads
            self._kits = [self._builds or kernels.builds(lv.rows, lv.cols, threads)
                          for lv in self.model.levels]

    def dinv(self, k, h):
        """``1 / (m_i + h^2 K_i)`` of level k, cached per step size."""
        key = (k, h)
        if key not in self._dinv:
            lv = self.model.level(k)
            self._dinv[key] = 1.0 / (lv.mass + h * h * lv.stiffness_sum)
        return self._dinv[key]

    def _prescribe(self, k, state, holds, h):
        self.kernels(k).prescribe(state.q[k], state.qd[k], holds.kind, holds.drive_index,
                                  holds.drive_target, h, self._presc[k])

    def _strain_limit(self, refinement):
        """Return a level's strain limit (``refinement``: its inherited points are fixed)."""
        return self.strain_limit

    def _post(self, k, state, holds, h, inherited_fixed):
        """
        Contact's friction pass, strain limiting, then contact: no point ends inside an obstacle.

        Moving bodies' surface velocity is their motion over the step's ``dt`` (``h`` is
        the velocity's scale, ``beta`` on the multigrid solver's BDF2 level below a refined
        finest level: ``MultigridSolver._corrections_leave_history``).
        """
        lv, kit = self.model.level(k), self.kernels(k)
        limit = self._strain_limit(inherited_fixed)
        scene = self.model.scene
        has_scene = scene is not None and not scene.empty
        # the finest level and every refinement level below it: a refinement level that
        # wrapped the obstacle hands the next one inherited points that already do
        wrap = limit is not None and (k == self._finest_now or inherited_fixed) and \
            self.contact_rounds and (len(self._bodies) or has_scene)
        integrated = None
        if wrap:    # the level as integrated, to tell which points post-processing moved
            integrated = self._integrated[k]
            np.copyto(integrated, self._q[k])
        touched = False
        if has_scene:
            # friction on the integration's motion, positions included, before strain
            # limiting moves points (kernels.contact)
            touched = kit.contact(self._q[k], self._qd[k], self._dv[k], state.q[k],
                                  holds.kind, inherited_fixed, scene.planes, scene.boxes,
                                  scene.spheres, scene.friction, scene.margin, self._dt,
                                  True) > 0
        if limit is not None:
            sweeps = kit.strain_limit(
                self._q[k], self._qd[k], self._dv[k], lv.rest, holds.kind, inherited_fixed,
                limit,
                self.strain_refine_iterations if inherited_fixed else self.strain_iterations,
                self.strain_tolerance, h, self._scratch[k])
            self._extra[f'strain_sweeps_{k}'] = sweeps
        if len(self._bodies):
            # before the static obstacles: a point squeezed between a body and the ground
            # ends on the ground, never inside it. Inherited points move too: a body holds
            # the points it presses on the finest level whether or not a coarser level has
            # them (a finger dragged a line of finest points away from the coarse ones
            # and stretched the springs between them to 270 %); the coarser levels take the
            # finest state at the end of the step.
            if self._body_contact(k, state, holds, h, scene):
                touched = True
                self._inject = self._inject or inherited_fixed
        if has_scene:
            touched |= kit.contact(self._q[k], self._qd[k], self._dv[k], state.q[k],
                                   holds.kind, inherited_fixed, scene.planes, scene.boxes,
                                   scene.spheres, scene.friction, scene.margin, self._dt,
                                   False) > 0
        self._touched |= touched
        if touched and wrap:
            if self.self_contact is None or k != self._finest_now:
                self._wrap(k, state, holds, h, limit, scene, integrated)
            else:       # after self-contact (see step)
                self._deferred = (k, holds, h, limit, scene)

    def _wrap(self, k, state, holds, h, limit, scene, integrated, velocity=None):
        """
        Alternate strain limiting and contact on level k, every point free.

        Contact pushes single points out and so stretches their springs; the coarser
        levels' straight segments cut through a table's edge, and the finer points wrapped
        round it between inherited points already too close (2.9 at 65 x 65 on the table
        scene). Here the inherited points move too, up to ``contact_rounds`` rounds of
        ``contact_sweeps`` sweeps, until strain limiting corrects nothing or contact pushes
        nothing. A level that contact left within the limit is left as it is (a cloth
        sliding on a plane). Every refinement level that touches does this before the next
        one steps, which then inherits points already round the edge (on the table scene at
        65 x 65 the peak strain fell from 0.22, the finest level alone wrapping, to 0.134);
        the coarser levels take the finest result at the end (:meth:`_inject_down`).
        ``integrated`` and ``velocity``: see :meth:`_pbd_velocity`.
        """
        kit = self.kernels(k)
        done = 0
        for rounds in range(1, self.contact_rounds + 1):
            if not self._round_strain_limit(k, holds, h, limit, scene):
                break   # within the limit, and the last contact left nothing inside
            done = rounds
            pushes = 0
            if len(self._bodies):
                pushes += self._body_contact(k, state, holds, h, scene)
            if scene is not None and not scene.empty:
                pushes += kit.contact(self._q[k], self._qd[k], self._dv[k], state.q[k],
                                      holds.kind, False, scene.planes, scene.boxes,
                                      scene.spheres, scene.friction, scene.margin, self._dt,
                                      False)
            if not pushes:
                break
        self._extra[f'contact_rounds_{k}'] = done
        if done:
            self._pbd_velocity(k, state, integrated, h, velocity)
            self._inject = True
        return done

    def _round_strain_limit(self, k, holds, h, limit, scene):
        """Strain limiting of one contact round on level k; returns its sweeps (0: none over)."""
        lv = self.model.level(k)
        if self.contact_strain == 'jacobi':
            return self.kernels(k).strain_limit(
                self._q[k], self._qd[k], self._dv[k], lv.rest, holds.kind, False, limit,
                self.contact_sweeps, self.strain_tolerance, h, self._scratch[k])
        scene = scene or NO_SCENE
        return self.kernels(k).tangent_strain_limit(
            self._q[k], self._qd[k], self._dv[k], lv.rest, holds.kind, scene.planes,
            scene.boxes, scene.spheres, self._bodies, scene.margin, scene.friction, limit,
            self.contact_sweeps, self.strain_tolerance, h, self.contact_relaxation,
            self.contact_tethers)

    def _pbd_velocity(self, k, state, integrated, h, velocity=None):
        """
        Give the points the rounds moved the velocity of their motion.

        For the points whose position differs from ``integrated`` (the level before the
        rounds): ``(x - x_start) / h``, their motion over the step, or with ``velocity``
        (their velocities at ``integrated``) ``velocity + (x - integrated) / h``, that plus
        the rounds' own motion. Where strain limiting and contact fight (a table's corner)
        each round's velocity change adds up while the points stay put: the paper's solver
        kept 9 cm/s, the multigrid solver 6 cm/s, on points that moved 0.1-1.4 mm/s.
        After self-contact the rounds start from where it left the level (``velocity``):
        its response is inelastic, and the motion over the whole step turned its pushes
        into velocity: points it pushed back and forth started the next step further off
        (the folded drops of ``tools/folded_seeds.py --noise 1e-3``: 4 of 20 seeds over
        strain 1 so, 1 with this; doc/self_contact_log.md).
        """
        moved = np.any(self._q[k] != integrated, axis=0)
        if moved.any():
            if velocity is None:
                new = (self._q[k][:, moved] - state.q[k][:, moved]) / h
            else:
                new = velocity[:, moved] + (self._q[k][:, moved] - integrated[:, moved]) / h
            self._dv[k][:, moved] += new - self._qd[k][:, moved]
            self._qd[k][:, moved] = new

    def _body_contact(self, k, state, holds, h, scene):
        """Run the moving bodies' contact on level k, every point free; return the pushes."""
        margin, planes, friction = (MARGIN, NO_PLANES, 0.0) if scene is None else \
            (scene.margin, scene.planes, scene.friction)
        return self.kernels(k).body_contact(self._q[k], self._qd[k], self._dv[k], state.q[k],
                                            holds.kind, False, self._bodies, margin, h,
                                            self._dt, planes, friction)

    def checkpoint(self):
        """Return what :meth:`restore` needs to undo committed steps (self-contact's memory)."""
        return None if self.self_contact is None else self.self_contact.checkpoint()

    def restore(self, checkpoint):
        """Undo the steps committed since ``checkpoint``; the caller restores the state."""
        if self.self_contact is not None and checkpoint is not None:
            self.self_contact.restore(checkpoint)

    def solves(self, k):
        """
        Whether level k is solved whole, not refined from a coarser one by eq. 7.

        A refined level follows its coarser level's shape; a solved one can crumple
        finer than any coarser level (self-contact's ``edges`` 'auto' tests all its edges).
        """
        return False

    def _inject_down(self, levels):
        """Give every coarser level the finest simulated level's state where they share points."""
        kit = self.kernels(levels[-1])
        for fine in range(levels[-1], levels[0], -1):
            for arrays in (self._q, self._qd, self._dv):
                kit.inject(arrays[fine], arrays[fine - 1])

    def step(self, state, control, dt):
        """Advance ``state`` by ``dt`` seconds under ``control``; return a StepReport."""
        start = time.perf_counter()
        if not (np.isfinite(dt) and 0.0 < dt <= 1.0):
            return StepReport(False, f'dt must be in (0, 1] s, got {dt}')
        h = float(dt)
        self._use_threads(numba.get_num_threads())
        levels = self.levels()
        self._extra = {}
        self._touched = False      # whether an obstacle pushed a point this step
        self._bodies, self._dt = control.bodies.packed(), h
        self._finest_now = levels[-1]
        self._inject = False       # whether a body moved points a coarser level shares
        self._deferred = None      # the finest level's rounds, when self-contact runs first
        for k in levels:
            holds = control.holds(k)
            self._prescribe(k, state, holds, h)
            self._integrate(k, state, holds, h)
        if self._inject:
            self._inject_down(levels)
        checked = None
        if self.self_contact is not None:
            checked = self.self_contact.apply(self, levels, state, control.holds(levels[-1]), h)
            if checked is not None:
                self._extra['self_contact_pairs'] = checked
            if self._deferred is not None:
                k, holds, h_post, limit, scene = self._deferred
                self._deferred = None
                # the rounds' velocities: from where self-contact left the level (the
                # level as integrated is not needed after it: its buffer holds them)
                before, velocity = self._before_rounds[k], self._integrated[k]
                np.copyto(before, self._q[k])
                np.copyto(velocity, self._qd[k])
                if self._wrap(k, state, holds, h_post, limit, scene, before, velocity):
                    # the rounds moved points: self-contact has the last word again, round
                    # the points they moved (elsewhere its last call left nothing near)
                    later = self.self_contact.apply(self, levels, state, holds, h,
                                                    moved=np.any(self._q[k] != before, axis=0))
                    if later:
                        self._extra['self_contact_later_pairs'] = later
                    self._inject_down(levels)
        if self._extra.get('self_contact_refused'):
            report = StepReport(False, 'self-contact: a point moved more than the cloth is '
                                'long against the rest of it in one step (a gripper sent '
                                'far?): step refused, last good state kept',
                                levels=tuple(levels))
        else:
            report = self._check(levels, state)
        if report.ok:
            # the new state goes in by swapping arrays (no copy): State.q[k] and
            # State.qd[k] are other array objects after every step (see State)
            for k in levels:
                state.q[k], self._q[k] = self._q[k], state.q[k]
                state.qd[k], self._qd[k] = self._qd[k], state.qd[k]
            state.time += h
            control.commit()
            if self.self_contact is not None:
                self.self_contact.committed(levels[-1], state, checked is not None)
        report.seconds = time.perf_counter() - start
        report.extra.update(self._extra)
        return report

    def _check(self, levels, state):
        """
        Refuse a non-finite step or a runaway strain, judged on the finest level alone.

        Then, with ``retry_strain``, a stretched one (:meth:`_stretched`).

        After a step every coarser simulated level is the finest one's points at every
        other row and column (constraint C, the multigrid solver's injection, and the
        injection after contact or self-contact moved shared points), with their
        velocities: finite if it is, and no coarse spring stretched more than the largest
        of the fine springs along it (its length is at most theirs summed, its rest length
        their sum): test_multigrid.py checks that. Checking them too cost 0.2 ms of the
        257 x 257 step (tools/check_cost.py).
        """
        k = levels[-1]
        mx, mean, finite = self.kernels(k).strain_stats(self._q[k], self._qd[k],
                                                        self.model.level(k).rest)
        if not finite:
            return StepReport(False, f'non-finite state on level {k}: step refused, '
                              'last good state kept', levels=tuple(levels))
        if mx > self.blowup_strain:
            return StepReport(False, f'runaway strain {mx:.3g} > {self.blowup_strain:g} '
                              f'on level {k}: step refused, last good state kept',
                              max_strain=mx, levels=tuple(levels))
        return self._stretched(levels, state, mx) or \
            StepReport(True, max_strain=mx, mean_strain=mean, levels=tuple(levels))

    def _stretched(self, levels, state, mx):
        """
        Return the refusal of a step that stretched the finest springs to ``mx``, or None.

        Refused (``stretched``): past ``retry_strain``, on a step in which self-contact
        found pairs, from a start (``state``, not yet replaced) within it. The rest is
        computed only past it.
        """
        if self.retry_strain is None or not mx > self.retry_strain:
            return None
        if not (self._extra.get('self_contact_pairs')
                or self._extra.get('self_contact_later_pairs')):
            return None
        k = levels[-1]
        start = self.kernels(k).strain_stats(state.q[k], state.qd[k],
                                             self.model.level(k).rest)[0]
        if start > self.retry_strain:
            return None
        return StepReport(False, f'strain {mx:.3g} > retry_strain {self.retry_strain:g} on '
                          f'level {k} (from {start:.3g}): step refused, last good state kept',
                          max_strain=mx, levels=tuple(levels), stretched=True)


class _SingleLevel(Solver):

    def __init__(self, model, level=None, **options):
        super().__init__(model, **options)
        self.level = model.level_count - 1 if level is None else int(level)
        model.level(self.level)     # range check

    def levels(self):
        return [self.level]

    def solves(self, k):
        return k == self.level


class ExplicitSolver(_SingleLevel):
    """Symplectic Euler on one level."""

    name = 'explicit'

    def _integrate(self, k, state, holds, h):
        lv = self.model.level(k)
        self.kernels(k).explicit_step(state.q[k], state.qd[k], lv.mass, lv.rest, lv.stiffness,
                                      lv.contraction, holds.kind, self._presc[k], h,
                                      self.model.gravity, self._q[k], self._qd[k], self._dv[k])
        self._post(k, state, holds, h, False)


class ApproxSolver(_SingleLevel):
    """The paper's eq. 6 on one level."""

    name = 'approx'

    def _integrate(self, k, state, holds, h):
        _eq6(self, k, state, holds, h)
        self._post(k, state, holds, h, False)


def _eq6(solver, k, state, holds, h):
    lv, kit = solver.model.level(k), solver.kernels(k)
    ft, a = solver._scratch[k], solver._a[k]
    kit.eq6_first_sweep(state.q[k], state.qd[k], lv.mass, lv.rest, lv.stiffness,
                        lv.contraction, solver.dinv(k, h), holds.kind, solver._presc[k], h,
                        solver.model.gravity, solver.literal, ft, a)
    kit.eq6_second_sweep(state.q[k], state.qd[k], lv.stiffness, solver.dinv(k, h), holds.kind,
                         solver._presc[k], ft, a, h, solver.model.gravity, solver.literal,
                         solver._q[k], solver._qd[k], solver._dv[k])


class HierarchicalSolver(Solver):
    """
    The paper's Table 1 over levels ``0 .. finest_level``.

    ``finest_level`` may change between steps: :meth:`set_finest_level` restarts a level
    that comes back from the coarser state, so nothing jumps.
    """

    name = 'hierarchical'

    def __init__(self, model, finest_level=None, **options):
        super().__init__(model, **options)
        self.finest_level = model.level_count - 1 if finest_level is None else finest_level

    @property
    def finest_level(self):
        return self._finest

    @finest_level.setter
    def finest_level(self, k):
        self.model.level(int(k))
        self._finest = int(k)

    def levels(self):
        return list(range(self._finest + 1))

    def solves(self, k):
        return k == 0           # eq. 6; the finer levels are eq. 7 refinements

    def set_finest_level(self, k, state, control):
        """
        Simulate levels ``0 .. k`` from the next step; returns k.

        A level that comes back (not simulated while coarser ones moved on) restarts from
        the coarser level's state, positions and velocities prolonged, and the control
        re-takes its holds there (grasped points keep their place in the grasp frame).
        With self-contact the finest of them is then pushed out of itself
        (:meth:`SelfContact.settle`): the coarser level's crease may be tighter than it can
        hold.
        """
        self.model.level(int(k))
        restarted = range(self._finest + 1, int(k) + 1)
        for level in restarted:
            prolong_state(state, level)
            control.recapture(state, level)
        if self.self_contact is not None and len(restarted):
            self.self_contact.settle(self, int(k), state, control.holds(int(k)))
        self.finest_level = k
        return self._finest

    def _integrate(self, k, state, holds, h):
        if k == 0:
            _eq6(self, 0, state, holds, h)
            self._post(0, state, holds, h, False)
            return
        self._eq7(k, state, holds, h)
        self._post(k, state, holds, h, True)

    # whether eq. 7's inserted points also take level k-1's drift beyond h v+ (see
    # kernels.eq7.eq7_level): only where level k-1 moves otherwise than by h v+
    refine_drift = False

    def _eq7(self, k, state, holds, h):
        """Constraint C and eq. 7 on level k, from level k-1's velocity change prolonged."""
        lv, kit = self.model.level(k), self.kernels(k)
        kit.eq7_level(state.q[k], state.qd[k], lv.mass, lv.rest, lv.stiffness, lv.contraction,
                      self.dinv(k, h), holds.kind, self._presc[k], h, self.model.gravity,
                      self.literal, self._q[k - 1], self._qd[k - 1], self._dv[k - 1],
                      state.q[k - 1], self.refine_drift, self._q[k], self._qd[k],
                      self._dv[k])


class ImplicitSolver(_SingleLevel):
    """
    Backward Euler on one level, solved to a tolerance: the converged reference.

    Each Newton iteration solves ``(M - h^2 J(x + h v+)) dv = -R(v+)`` for the residual
    ``R(v+) = M (v+ - v) - h f(x + h v+) - h M g`` by CG, until the estimated
    remaining position error is below ``tolerance`` (m), or ``max_newton`` iterations
    have run (the report's ``converged`` says which); see :func:`_newton_done`.
    """

    name = 'implicit'

    def __init__(self, model, level=None, tolerance=1e-6, max_newton=100, cg_rtol=1e-6,
                 cg_max_iter=2000, **options):
        super().__init__(model, level=level, **options)
        if not (0 < tolerance < 1):
            raise ValueError(f'tolerance must be in (0, 1) m, got {tolerance}')
        if not (1 <= max_newton <= 1000 and 1 <= cg_max_iter <= 100000):
            raise ValueError('max_newton must be in 1..1000 and cg_max_iter in 1..100000')
        if not (0 < cg_rtol < 1):
            raise ValueError(f'cg_rtol must be in (0, 1), got {cg_rtol}')
        self.tolerance = float(tolerance)
        self.max_newton = int(max_newton)
        self.cg_rtol = float(cg_rtol)
        self.cg_max_iter = int(cg_max_iter)
        shape = self._q[self.level].shape
        self._work = [buffers.zeros(shape) for _ in range(8)]

    def _integrate(self, k, state, holds, h):
        lv, kit = self.model.level(k), self.kernels(k)
        q, qd = state.q[k], state.qd[k]
        f, rhs, delta, diag, r, z, p, ap = self._work
        free = (holds.kind == FREE).astype(np.float64)
        g = self.model.gravity[:, None, None]
        v_plus = self._qd[k]
        # explicit gravity as the first guess; held points get their prescribed velocity
        np.copyto(v_plus, np.where(free[None] > 0, qd + h * g, qd + self._presc[k]))
        x_eval = self._q[k]
        newton = cg_total = 0
        converged = False
        previous = None
        for newton in range(1, self.max_newton + 1):
            np.multiply(v_plus, h, out=x_eval)
            x_eval += q
            kit.spring_forces(x_eval, lv.rest, lv.stiffness, lv.contraction, f)
            # rhs = -R on free points, zero on held ones
            np.subtract(v_plus, qd, out=rhs)
            rhs *= -lv.mass
            rhs += h * f
            rhs += (h * lv.mass) * g
            rhs *= free
            kit.system_diagonal(x_eval, lv.rest, lv.stiffness, lv.contraction, lv.mass, free,
                                h, diag)
            iters, _ = kit.conjugate_gradient(x_eval, lv.rest, lv.stiffness, lv.contraction,
                                              lv.mass, free, h, rhs, delta, diag, self.cg_rtol,
                                              self.cg_max_iter, r, z, p, ap)
            cg_total += iters
            v_plus += delta
            change = h * np.max(np.abs(delta))
            if _newton_done(change, previous, self.tolerance):
                converged = True
                break
            previous = change
        np.multiply(v_plus, h, out=x_eval)
        x_eval += q
        np.subtract(v_plus, qd, out=self._dv[k])
        self._extra = {'newton_iterations': newton, 'cg_iterations': cg_total,
                       'converged': converged}
        self._post(k, state, holds, h, False)

    def step(self, state, control, dt):
        report = super().step(state, control, dt)
        report.newton_iterations = report.extra.get('newton_iterations', 0)
        report.cg_iterations = report.extra.get('cg_iterations', 0)
        report.converged = report.extra.get('converged', True)
        return report


def _newton_done(change, previous, tolerance):
    """
    Whether Newton's remaining error is below ``tolerance``.

    ``change`` is this iteration's largest position update ``h |dv|_inf`` (m),
    ``previous`` the last one (None on the first iteration). The Newton matrix clamps the
    transverse stiffness of compressed springs to stay positive definite, so convergence
    can be linear with rate ``rho = change / previous``; the iterations still to come then
    add up to at most ``change * rho / (1 - rho)``. Stop when both that and ``change``
    are below the tolerance; with no rate yet, only on a change ten times smaller.
    """
    if previous is None:
        return change < 0.1 * tolerance
    rho = change / previous if previous > 0 else 0.0
    if rho >= 1.0:
        return False
    return change * max(1.0, rho / (1.0 - rho)) < tolerance


# the multigrid solver builds on HierarchicalSolver, so its module imports this one: it
# comes last (the package imports this module first, whichever module a user imports)
from hcloth_ros.core.multigrid_solver import MultigridSolver  # noqa: E402, I100

SOLVERS = {cls.name: cls for cls in
           (ExplicitSolver, ApproxSolver, HierarchicalSolver, ImplicitSolver, MultigridSolver)}


def make_solver(name, model, **options):
    """Build the solver called ``name`` (one of :data:`SOLVERS`)."""
    if name not in SOLVERS:
        raise ValueError(f'unknown solver {name!r}; choose one of {sorted(SOLVERS)}')
    return SOLVERS[name](model, **options)


def prolong_state(state, k):
    """Restart level k from level k-1's state (positions and velocities, no jump)."""
    kernels.SERIAL.prolong(state.q[k - 1], state.q[k])
    kernels.SERIAL.prolong(state.qd[k - 1], state.qd[k])
