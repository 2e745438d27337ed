"""
What the outside world sets: pinned points, grasps and kinematic targets.

Everything is given in point ids of the finest level (see :mod:`hcloth_ros.core.model`).
A hold is made consistent across levels here, so a coarse level never drags a held fine
point's neighbourhood away: on a level where a pinned id does not exist, its
representative (the anchor chain of first parents, :meth:`ClothModel.representative`) is
pinned; a grasp holds its footprint there (both end points of the edge the id was
inserted on, recursively, :meth:`ClothModel.footprint`), rigid with the grasp frame.

* A pinned point does not move at all, bit for bit, on every level where it (or its
  representative) is held.
* A grasp attaches points rigidly to a frame (rotation ``R``, translation ``p``): each
  held point keeps the coordinates it had in that frame when grasped, on every level, so
  moving the frame carries the cloth as a whole.
* A kinematic target drives one point to a position each step: a one-point grasp whose
  frame is translated only.

Pins win over grasps for a point that is both.
"""

from dataclasses import dataclass

# the hold kinds are the kernels' (re-exported here for the engine's users)
from hcloth_ros.core import buffers
from hcloth_ros.core.bodies import MovingBodies
from hcloth_ros.core.kernels.layout import DRIVEN, FREE, PINNED  # noqa: F401
from hcloth_ros.core.poses import check_rotation, check_vector, part_way
import numpy as np


@dataclass
class _Grasp:
    rotation: np.ndarray        # (3, 3), at the end of the next step
    translation: np.ndarray     # (3,)
    grid_index: list            # per level: int64 (m,)
    local: list                 # per level: float64 (3, m), coordinates in the frame
    start_rotation: np.ndarray = None     # at the end of the last committed step
    start_translation: np.ndarray = None


@dataclass
class Plan:
    """
    Where every grasp frame and moving body starts and ends the coming step(s).

    Taken by :meth:`Control.plan` before a span of time is cut into several steps (a
    tick's substeps, a refused step's retries): ``grasps`` and ``bodies`` map a name to
    ``((start rotation, start translation), (end rotation, end translation))``.
    """

    grasps: dict
    bodies: dict


@dataclass
class Holds:
    """
    One level's resolved holds, as the kernels read them.

    ``kind``: int8 ``(rows, cols)`` of FREE / PINNED / DRIVEN. ``drive_index``: flat grid
    indices of driven points. ``drive_target``: ``(3, m)`` positions they must reach at
    the end of the step (m).
    """

    kind: np.ndarray
    drive_index: np.ndarray
    drive_target: np.ndarray


class Control:
    """
    Pins, grasps and targets of one cloth; create with ``Control(model)``.

    ``bodies``: the moving obstacles (:class:`~hcloth_ros.core.bodies.MovingBodies`).
    """

    def __init__(self, model):
        self.model = model
        self.bodies = MovingBodies()
        self._pins = {}
        self._grasps = {}
        self._version = 0
        self._kind_cache = None

    # --- validation -------------------------------------------------------------------
    def _check_ids(self, ids):
        arr = np.asarray(ids)
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f'point ids must be integers, got {arr.dtype}')
        arr = arr.astype(np.int64).ravel()
        bad = arr[(arr < 0) | (arr >= self.model.point_count)]
        if bad.size:
            raise IndexError(f'point ids {bad.tolist()[:5]} out of range '
                             f'0..{self.model.point_count - 1}')
        return arr

    # --- pins -------------------------------------------------------------------------
    @property
    def pins(self):
        return np.fromiter(self._pins, dtype=np.int64, count=len(self._pins))

    def set_pins(self, ids):
        """Replace the pinned set (ids are checked before anything changes)."""
        arr = self._check_ids(ids)
        self._pins = dict.fromkeys(arr.tolist())
        self._touch()

    def pin(self, ids):
        arr = self._check_ids(ids)
        self._pins.update(dict.fromkeys(arr.tolist()))
        self._touch()

    def unpin(self, ids):
        for i in self._check_ids(ids).tolist():
            self._pins.pop(i, None)
        self._touch()

    # --- grasps -----------------------------------------------------------------------
    @property
    def grasp_names(self):
        return list(self._grasps)

    def grasp(self, name, ids, state, rotation=np.eye(3), translation=(0, 0, 0)):
        """
        Attach ``ids`` rigidly to a frame whose pose is ``(rotation, translation)`` now.

        Re-grasping an existing name replaces it.
        """
        arr = self._check_ids(ids)
        if arr.size == 0:
            raise ValueError(f'grasp {name!r} needs at least one point')
        r = check_rotation(rotation).copy()      # the caller may reuse its arrays
        p = check_vector(translation, 'translation').copy()
        grid_index, local = [], []
        for k in range(self.model.level_count):
            reps = np.unique(sorted(set().union(*(self.model.footprint(i, k)
                                                  for i in arr.tolist()))))
            g = self.model.level(k).id_to_grid[reps]
            x = state.q[k].reshape(3, -1)[:, g]
            grid_index.append(np.ascontiguousarray(g))
            local.append(np.ascontiguousarray(r.T @ (x - p[:, None])))
        self._grasps[name] = _Grasp(r, p, grid_index, local, r, p)
        self._touch()

    def move_grasp(self, name, rotation, translation):
        """
        Set a grasp frame's pose at the end of the next step; its points follow rigidly.

        They move there from where the frame was at the end of the last committed step
        (its pose when grasped, for a new grasp). A pose that stays set for several steps
        (:meth:`follow`) is reached evenly over them.
        """
        if name not in self._grasps:
            raise KeyError(f'no grasp named {name!r} (have {self.grasp_names})')
        rotation = check_rotation(rotation).copy()
        translation = check_vector(translation, 'translation').copy()
        g = self._grasps[name]
        g.rotation, g.translation = rotation, translation

    def recapture(self, state, k):
        """
        Re-take every grasp's frame coordinates on level k from its current state.

        A level that was not simulated when a grasp closed holds stale coordinates; after
        it is restarted from the coarser state (``prolong_state``) this keeps its grasped
        points where they are and rigid with the frame from now on, instead of jumping.
        """
        for g in self._grasps.values():
            # the state is where the last committed step left the frame, not where the
            # next step takes it
            x = state.q[k].reshape(3, -1)[:, g.grid_index[k]]
            g.local[k] = np.ascontiguousarray(
                g.start_rotation.T @ (x - g.start_translation[:, None]))

    def release(self, name):
        if self._grasps.pop(name, None) is not None:
            self._touch()

    def release_all(self):
        self._grasps.clear()
        self._touch()

    def grasped_ids(self, name):
        """Finest-level grid indices held by a grasp (for display)."""
        return self._grasps[name].grid_index[-1].copy()

    # --- the motion of a step --------------------------------------------------------
    def commit(self):
        """
        Start the next step where every grasp frame and body is now.

        The solver calls it after a committed step; a grasp frame that is not moved again
        then holds its points still.
        """
        for g in self._grasps.values():
            g.start_rotation, g.start_translation = g.rotation, g.translation
        self.bodies.commit()

    def plan(self):
        """Return where grasps and bodies start and end the next step (a :class:`Plan`)."""
        return Plan({name: ((g.start_rotation, g.start_translation),
                            (g.rotation, g.translation))
                     for name, g in self._grasps.items()}, self.bodies.plan())

    def follow(self, plan, s):
        """
        Ask every grasp and body of ``plan`` to be a fraction ``s`` of its way at the step's end.

        Cutting a span into n steps, step i (from 1) follows ``i / n``: the grasped points
        and the bodies then move evenly over the span, at the speed the span's poses ask,
        instead of reaching their poses in the first step and resting. ``s`` = 1 puts them
        back at the plan's ends. Grasps released since the plan are left alone.
        """
        for name, (start, end) in plan.grasps.items():
            g = self._grasps.get(name)
            if g is not None:
                g.rotation, g.translation = part_way(start, end, s)
        self.bodies.follow(plan.bodies, s)

    def rewind(self, plan):
        """Undo the steps taken since ``plan``: every start and end as it says."""
        for name, (start, end) in plan.grasps.items():
            g = self._grasps.get(name)
            if g is not None:
                (g.start_rotation, g.start_translation), (g.rotation, g.translation) = \
                    start, end
        self.bodies.rewind(plan.bodies)

    # --- kinematic targets ------------------------------------------------------------
    def set_target(self, point_id, position, state):
        """Drive one point to ``position`` (m) from the next step on."""
        pos = check_vector(position, 'target position')
        pid = int(self._check_ids([point_id])[0])
        name = ('target', pid)
        if name not in self._grasps:
            here = state.position_of(self.model, pid, self.model.level_count - 1)
            self.grasp(name, [pid], state, np.eye(3), here)
        self.move_grasp(name, np.eye(3), pos)

    def clear_target(self, point_id):
        self.release(('target', int(self._check_ids([point_id])[0])))

    # --- resolution ---------------------------------------------------------------------
    def _touch(self):
        self._version += 1
        self._kind_cache = None

    def _kinds(self):
        """Per-level hold kinds; recomputed only when pins or grasps change."""
        if self._kind_cache is not None:
            return self._kind_cache
        model = self.model
        kinds, drive = [], []
        for k in range(model.level_count):
            lv = model.level(k)
            kind = buffers.zeros(lv.rows * lv.cols, dtype=np.int8)
            sources = []
            for name, g in self._grasps.items():
                kind[g.grid_index[k]] = DRIVEN
                sources.append(name)
            pinned = [model.representative(i, k) for i in self._pins]
            kind[lv.id_to_grid[np.asarray(pinned, dtype=np.int64)]] = PINNED
            kinds.append(kind.reshape(lv.rows, lv.cols))
            drive.append(sources)
        self._kind_cache = kinds
        return kinds

    def holds(self, k):
        """Resolve level k's holds for the coming step (targets from current frames)."""
        kind = self._kinds()[k]
        flat = kind.ravel()
        index, target = [], []
        for g in self._grasps.values():
            gi = g.grid_index[k]
            keep = flat[gi] == DRIVEN    # a pin on the same point wins
            index.append(gi[keep])
            target.append(g.rotation @ g.local[k][:, keep] + g.translation[:, None])
        if index:
            idx = np.concatenate(index)
            tgt = np.ascontiguousarray(np.concatenate(target, axis=1))
        else:
            idx = np.zeros(0, dtype=np.int64)
            tgt = np.zeros((3, 0))
        return Holds(kind, idx, tgt)
