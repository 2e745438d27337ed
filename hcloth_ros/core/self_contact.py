"""
Self-contact as a solver runs it: on the finest simulated level, every n-th step.

The kernel (:mod:`hcloth_ros.core.kernels.self_contact`) keeps one level's points a
thickness away from its own triangles and stops them crossing one between two positions.
This module decides which level, between which positions, and what the coarser levels do
afterwards.
"""

import math

from hcloth_ros.core.kernels.self_contact import BOXES_KEPT, BOXES_KEPT_NEW_START, \
    BOXES_NEW, carry, CREASE_ANGLE, obstacle_supports, patch_cache
import numpy as np

# Rounds of self-contact and strain limiting a check runs at most (see SelfContact.apply).
ROUNDS = 3
# Which edges are tested against edges (see SelfContact), and the kernel's crease angle of
# each but auto: the most an edge may bend and not be tested
EDGES = ('auto', 'creases', 'sharp', 'all')
CREASE_ANGLES = {'creases': CREASE_ANGLE, 'sharp': math.pi, 'all': 0.0}


def thickness_warning(model, thickness):
    """
    Return why ``thickness`` is too thick for the model's finest level, or None.

    The kernel assumes the thickness is below the finest grid spacing: it skips the
    triangles within ``RING`` rows and columns of a point (two rows of springs cannot
    fold within a thickness below the spacing without stretching) and culls patches whose
    normals stay within a cone (a flat patch cannot come within a thickness of itself).
    At one spacing or more a pleat touches itself unseen: the folded drop at 257 x 257,
    4 mm on a 3.9 mm spacing, stretched springs to 1.68 where 129 x 129 (7.8 mm) stayed
    at 0.31-0.90 (README, tangles).
    """
    lv = model.level(model.level_count - 1)
    spacing = min(lv.rest[0], lv.rest[2])       # along a row, down a column
    if thickness is None or thickness < spacing:
        return None
    return (f'self_contact.thickness {thickness:g} m is not below the finest grid spacing '
            f'{spacing:.3g} m ({lv.rows} x {lv.cols} points on {model.width:g} x '
            f'{model.height:g} m): self-contact misses folds tighter than a few '
            f'spacings; keep the thickness under about half the spacing '
            f'({0.5 * spacing:.2g} m), or use fewer levels or a coarser cloth.resolution')


def solved_level_warning(solver):
    """
    Return why the solver's finest level will stretch in contact, or None.

    The multigrid solver solving the finest simulated level itself, with self-contact
    and no ``solved_strain_limit``: the solve holds the springs, but the contact passes
    after it move points with nothing to pull their neighbours after them (the folded
    drop at 129 x 129, ``accurate_level`` 4: 0.72, against 0.11 with 0.1; 1.7 and 0.14
    while BDF2's history kept those passes' corrections).
    """
    finest = solver.levels()[-1]
    if solver.self_contact is None or not hasattr(solver, 'solved_strain_limit') or \
            solver.solved_strain_limit is not None or not solver.solves(finest):
        return None
    return (f'multigrid solves the finest level ({finest}, solver.accurate_level '
            f'{solver.accurate_level}) with self-contact and no solver.solved_strain_limit: '
            f'contact will stretch its springs with nothing pulling them back (0.72 in the '
            f'129 x 129 folded drop); set solver.solved_strain_limit (0.1: 0.11 there)')


def _up(model):
    """Return the unit vector against the model's gravity (zero without gravity)."""
    g = np.asarray(model.gravity, dtype=np.float64)
    norm = np.linalg.norm(g)
    return -g / norm if norm > 0.0 else np.zeros(3)


def supports(scene, q, out):
    """
    Write into ``out`` (4, rows, cols) the obstacle below each point and its room to it.

    ``out[:3]`` the obstacle's outward unit normal, ``out[3]`` the point's distance to the
    obstacle grown by the scene's margin (at least 0): the nearer of the planes and of the
    boxes' tops it lies on or over (inside the top face grown by the margin, not below
    it: a point hanging beside a box is not on its top). No such obstacle: normal 0, room
    infinite. Self-contact moves a point towards its obstacle by at most its room.
    Spheres and moving bodies are not supports, and of two planes a point is near only
    the nearer counts (the scenes have one plane, the ground). Strain limiting between
    self-contact's rounds does not look at supports.
    """
    if scene is None or scene.empty:
        out[:3] = 0.0
        out[3] = np.inf
        return out
    obstacle_supports(scene.planes, scene.boxes, scene.margin, q, out)
    return out


class SelfContact:
    """
    Settings and memory of the cloth's self-contact.

    :param thickness: points stay this far (m) from the triangles of their own level.
    :param friction: friction coefficient between layers of the cloth.
    :param iterations: most rounds of detection and response in one kernel call (then one
        more that moves points alone).
    :param interval: check every n-th step (1: every step). Between checks the cloth may
        pass through itself; the check then runs from the positions of the last one, so
        a point that ended up on the other side of a triangle is brought back (a crossing
        that is undone within the interval goes unseen).
    :param edges: which edges besides the free borders are tested against edges:
        ``'sharp'``, those bent enough for an edge to pass under them with its ends a
        thickness clear of them (93 degrees at 4 mm on the 129 x 129 bench's 7.8 mm
        spacing); ``'creases'``, those and every edge bent past 10 degrees (an edge's
        ends keep the thickness only at the ends of a step: the double fold, its layers
        meeting fast, tangled in 6 of 44 runs with ``'sharp'`` and none with
        ``'creases'``, at 1.2-1.9 times the cost where layers touch);
        ``'all'``, every bent edge (a cloth crumpled in compression hooks edges a few
        rows apart that bend less), 1.2-1.3 times the cost of ``'creases'`` (2.1-2.8
        before the edges' tests used the points' block lists, 2026-11-30); ``'auto'``,
        all on a level the solver solves itself (:meth:`Solver.solves`: multigrid's
        accurate level, which let the folded drop crumple so), creases elsewhere. The
        kernel's ``crease_angle``: :func:`~hcloth_ros.core.kernels.self_contact._crease_cosine`.
    """

    def __init__(self, thickness, friction=0.3, iterations=8, interval=1, edges='auto'):
        if not (np.isfinite(thickness) and 0.0 < thickness <= 0.1):
            raise ValueError(f'thickness must be in (0, 0.1] m or None, got {thickness}')
        if not (np.isfinite(friction) and 0.0 <= friction <= 10.0):
            raise ValueError(f'self_friction must be in [0, 10], got {friction}')
        for name, value, high in (('self_contact_iterations', iterations, 100),
                                  ('self_contact_interval', interval, 1000)):
            if not 1 <= int(value) <= high:
                raise ValueError(f'{name} must be in 1..{high}, got {value}')
        if edges not in EDGES:
            raise ValueError(f'self_contact_edges must be one of {EDGES}, got {edges!r}')
        self.edges = edges
        self.thickness = float(thickness)
        self.friction = float(friction)
        self.iterations = int(iterations)
        self.interval = int(interval)
        self._start = None          # finest positions at the last check (interval > 1)
        self._key = None            # (level, time) the next step must start from
        self._steps = 0             # steps since the last check
        self._moved = self._before = self._support = None   # buffers of apply
        self._clean = None          # where this step's last clean call left the level
        self._clean_key = None      # (level, time) of the step that _clean is of
        self._pending = None        # points the step's last call pushed unchecked
        self._pending_key = None    # (level, time) of the step that _pending is of
        self._reuse = BOXES_NEW     # what the next call may keep of the last one's boxes
        self._patches = None        # what the kernel keeps between a step's calls
        self._noted = None          # the triangles points lie on after the last committed step
        self._uncommitted = False   # whether a step since then changed them

    def _due(self, k, state):
        """
        Return whether this step checks.

        The count and the start positions restart when the state is not where the last
        step left it in time (a reset) or the finest level changed. A state edited
        without a change of time is not noticed.
        """
        if self._restarted(k, state):
            self._steps = 0
            self._start = state.q[k].copy() if self.interval > 1 else None
        return self._steps + 1 >= self.interval

    def _restarted(self, k, state):
        """Whether ``state`` is not where the last step left level k (a reset, another level)."""
        return self._key != (k, state.time)

    def apply(self, solver, levels, state, holds, h, moved=None):
        """
        Run on the finest of ``levels`` (the solver's step buffers), then down the hierarchy.

        Every free point may move (inherited ones too); the coarser levels then take the
        finest level's state at the points they share, so they start the next step where
        the contact left the cloth instead of dragging it back through itself. Pushes
        move single points: strain limiting (if the solver has it) spreads them to their
        neighbours, then contact runs again, as it may have pulled points back in, up to
        ``ROUNDS`` times. Returns the pairs found, or None when this step does not check.
        Before it, every step, checked or not, the points lying on a layer are kept on it
        (:meth:`_carry`), so that a layer at rest on another is not found in it again.

        ``moved`` (a mask of the level's points), for a second call in the same step: the
        points moved since the last call, which left nothing near; the first detection
        then tests round them only and keeps the other patches' boxes (None: every point,
        every box). If the last call's rounds ran out, the points it moved are added: its
        last pushes were not checked. A call after the step's first tests the paths from
        where the last call that ended clean left the level (:meth:`_ended`), not from the
        step's start.

        Obstacles do not run after it. A point above a plane or a box's top moves towards
        it by at most its distance to the obstacle's margin (:func:`supports`, taken at
        the start of each round); a layer lying on it stays and the layer above moves
        alone. Without that a bottom layer
        pressed onto the ground by the top one ended up to 2.6 mm below the ground
        (folded drop, 5 mm thickness); running the obstacles after each round instead
        doubled the folded drop's largest strain (129 x 129) and got 257 x 257 refused
        (issue 10's note).
        """
        k, up = levels[-1], _up(solver.model)
        carried = self._carry(solver, k, state, holds, h, up) if moved is None else 0
        if not self._due(k, state):
            if carried:
                solver._inject_down(levels)
            return None
        lv, kit = solver.model.level(k), solver.kernels(k)
        span = (self._steps + 1) * h    # the time the kernel's paths cover
        pairs, dropped = None, 0
        mask, before, support = self._buffers(lv.shape)
        if moved is None:
            mask[:] = True
            self._clean_key = None
        else:
            np.copyto(mask, moved)
            if self._pending_key == (k, state.time):
                mask |= self._pending
            if not mask.any():
                return 0
        self._pending_key = None
        step_start = state.q[k] if self._start is None else self._start
        start, reuse = self._path_start(k, state, step_start, moved is not None)
        edges = self.edges
        if edges == 'auto':
            edges = 'all' if solver.solves(k) else 'creases'
        crease_angle = CREASE_ANGLES[edges]
        for attempt in range(ROUNDS):
            np.copyto(before, solver._q[k])
            supports(solver.model.scene, solver._q[k], support)
            found, _, lost, clean = kit.self_contact(
                solver._q[k], solver._qd[k], solver._dv[k], step_start, start, lv.mass,
                holds.kind, mask, support, self.thickness, self.friction, self.iterations,
                span, max(solver.model.width, solver.model.height), up, *self._patches,
                reuse, crease_angle)
            if found < 0:
                solver._extra['self_contact_refused'] = True
                return None
            pairs = found if pairs is None else pairs
            dropped = max(dropped, lost)
            start, reuse = self._ended(k, state, solver._q[k], clean, start)
            if not found or solver.strain_limit is None or attempt == ROUNDS - 1:
                break
            kit.strain_limit(solver._q[k], solver._qd[k], solver._dv[k], lv.rest, holds.kind,
                             False, solver.strain_limit, solver.strain_refine_iterations,
                             solver.strain_tolerance, h, solver._scratch[k])
            # the next call tests round the points moved since its paths' start: since
            # this call ended, if it ended clean (strain limiting's moves alone: a point
            # only this call pushed has an empty path from there), else since this
            # call's first detection. The kernel recomputes the patch boxes there and
            # where this call moved points. None moved: done
            np.any(solver._q[k] != (self._clean if clean else before), axis=0, out=mask)
            if not mask.any():
                break
        if not clean:
            # the last call's last pushes were not checked (its rounds ran out, or this
            # apply's): the step's next call tests round the points it moved too (without,
            # the obstacles' rounds' call tested round their moves alone: a restored fold
            # ended a step with a pair 0.4 % within the thickness, session 45)
            np.any(solver._q[k] != before, axis=0, out=self._pending)
            self._pending_key = (k, state.time)
        if dropped:
            solver._extra['self_contact_dropped'] = dropped
        if pairs or carried:
            solver._inject_down(levels)
        return pairs

    def _path_start(self, k, state, step_start, again):
        """
        Return where this call's paths start and whether the last call's boxes still fit.

        The step's first call: at ``step_start`` (the step's, or the last check's). A
        later call (``again``): where the last call of this step that left nothing near
        ended, if one did (:meth:`_ended`), else at ``step_start`` too.
        """
        if again and self._clean_key == (k, state.time):
            return self._clean, self._reuse
        return step_start, (BOXES_KEPT if again else BOXES_NEW)

    def _ended(self, k, state, q, clean, start):
        """
        Note where a call left the level; return where the next call's paths start.

        A call whose last detection found nothing left no point within the thickness of a
        triangle and none crossed on its way there: the step's next calls (after strain
        limiting, after the obstacles' rounds) test the paths from there, the short moves
        those made, instead of the step's whole sweep again from its start (on the folded
        drop's sliding layers each later call tested ~1,000 moved points over their
        16 mm sweep, as dear as half the first detection). A call that did not end clean
        (its rounds ran out) leaves the start where it was, and its boxes fit the next.
        """
        if clean:
            np.copyto(self._clean, q)
            self._clean_key = (k, state.time)
            self._reuse = BOXES_KEPT_NEW_START
            return self._clean, self._reuse
        self._reuse = BOXES_KEPT
        return start, self._reuse

    def _carry(self, solver, k, state, holds, h, up):
        """
        Let the layers the points lie on carry them this step (kernel ``carry``); return how many.

        Every step, checked or not. What a point lies on is known from the pushes of the
        checks before (the kernel notes them); after a reset or a change of the finest
        level it is forgotten. A refused step's notes are of positions the retry does not
        start from: they go back to the last committed step's (:meth:`committed`).
        ``self_contact_carried`` in the step's report: the points carried.
        """
        lv = solver.model.level(k)
        _, _, support = self._buffers(lv.shape)
        lies_on = self._patches[-1]
        if self._restarted(k, state):
            lies_on[:] = -1     # (the kernel still runs: a solver's first step compiles it)
        elif self._uncommitted:
            np.copyto(lies_on, self._noted)
        self._uncommitted = True
        supports(solver.model.scene, solver._q[k], support)
        count = carry(solver._q[k], solver._qd[k], solver._dv[k], state.q[k], lv.mass,
                      holds.kind, support, lies_on, up, self.thickness, self.friction, h,
                      self._patches[-2])
        solver._extra['self_contact_carried'] = count
        return count

    def settle(self, solver, k, state, holds):
        """
        Push level k, just restarted from the coarser level, out of its own triangles.

        Returns the pairs found. The coarser level kept its points a thickness from its
        triangles except within ``RING`` of its own rows and columns, twice as far on the
        cloth as level k's ring: at a crease tighter than that the restarted level starts
        with points lying level with, or in, the other layer's first cells, and nothing
        tells which side they came from (the 33 x 33 fold demo's crease restored at 65 x
        65 put 6-8 top-layer points below the bottom layer, for good). The kernel
        (``settle``) puts each such point on the side its own surface lies on and pushes
        the pairs apart, positions only, before the level's first step; the coarser
        levels then take those positions where they share points.
        """
        lv, kit = solver.model.level(k), solver.kernels(k)
        _, _, support = self._buffers(lv.shape)
        supports(solver.model.scene, state.q[k], support)
        pairs = kit.settle(state.q[k], lv.mass, holds.kind, support, self.thickness,
                           self.iterations, *self._patches)
        if pairs:
            for fine in range(k, 0, -1):
                kit.inject(state.q[fine], state.q[fine - 1])
        return pairs

    def _buffers(self, shape):
        """Return the moved-points mask, a positions copy and the supports of a level."""
        if self._moved is None or self._moved.shape != tuple(shape):
            self._moved = np.ones(shape, dtype=np.bool_)
            self._before = np.empty((3,) + tuple(shape))
            self._support = np.empty((4,) + tuple(shape))
            self._clean = np.empty((3,) + tuple(shape))
            self._clean_key = None
            self._pending, self._pending_key = np.zeros(shape, dtype=np.bool_), None
            self._patches = patch_cache(*shape)
            self._noted, self._uncommitted = self._patches[-1].copy(), False
        return self._moved, self._before, self._support

    def checkpoint(self):
        """
        Return what a committed step leaves here, for :meth:`restore` after undoing steps.

        A retry's smaller steps commit one by one; when a later one is refused the state
        goes back to the retry's start, and so must the step count, the last check's
        positions and the notes of what lies on what.
        """
        return (self._key, self._steps, None if self._start is None else self._start.copy(),
                None if self._noted is None else self._noted.copy())

    def restore(self, checkpoint):
        """Go back to a :meth:`checkpoint` (the state went back to where it was taken)."""
        self._key, self._steps, start, noted = checkpoint
        self._start = None if start is None else start.copy()
        if noted is not None:       # (a retry keeps the level, and so the shape)
            np.copyto(self._noted, noted)
            self._uncommitted = True    # the next step starts from these notes

    def committed(self, k, state, checked):
        """Remember where the next step starts (the step to ``state`` was accepted)."""
        if self._uncommitted:
            np.copyto(self._noted, self._patches[-1])
            self._uncommitted = False
        self._key = (k, state.time)
        self._steps = 0 if checked else self._steps + 1
        if checked and self._start is not None:
            np.copyto(self._start, state.q[k])
