"""
Moving obstacles: named rigid bodies (box, sphere, capsule) whose pose the outside world sets.

A body takes part in contact from its first pose on. Each pose set is where the body is at
the end of the next step; it moves rigidly there from where it was at the end of the last
committed step, and the cloth meets its surface velocity (friction drags, a rising body
lifts). Bodies are kept by :class:`~hcloth_ros.core.control.Control` (``control.bodies``)
beside the grasps: both are what the outside world moves. The kernel is
:mod:`hcloth_ros.core.kernels.bodies`.

Sizes (m): a box's three half extents, a sphere's radius, a capsule's radius and half
length (its axis is the body's z axis, a finger's or a link's length).
"""

from dataclasses import dataclass

from hcloth_ros.core.kernels import bodies as layout
from hcloth_ros.core.poses import check_rotation, check_vector, part_way
import numpy as np

# sizes each shape takes and its kernel code
SHAPES = {'box': (layout.BOX, 3), 'sphere': (layout.SPHERE, 1),
          'capsule': (layout.CAPSULE, 2)}
MAX_BODIES = 64


@dataclass
class _Body:
    kind: int
    size: tuple
    friction: float
    rotation: np.ndarray = None         # at the end of the next step
    translation: np.ndarray = None
    start_rotation: np.ndarray = None   # at the end of the last committed step
    start_translation: np.ndarray = None


class MovingBodies:
    """The moving obstacles of one cloth, by name."""

    def __init__(self):
        self._bodies = {}
        self._packed = None

    def __len__(self):
        return len(self._bodies)

    def __contains__(self, name):
        return name in self._bodies

    def names(self):
        return sorted(self._bodies)

    def add(self, name, shape, size, friction=0.5):
        """
        Declare a body; it takes part from its first :meth:`set_pose` on.

        :param shape: ``'box'``, ``'sphere'`` or ``'capsule'``.
        :param size: half extents (box, 3), radius (sphere, 1), radius and half length
            (capsule, 2), in m, each positive.
        :param friction: Coulomb coefficient between the body and the cloth, >= 0.
        """
        if not isinstance(name, str) or not name or name in self._bodies:
            raise ValueError(f'body name must be a new non-empty string, got {name!r}')
        if len(self._bodies) >= MAX_BODIES:
            raise ValueError(f'at most {MAX_BODIES} moving bodies')
        if shape not in SHAPES:
            raise ValueError(f'body {name}: shape must be one of {sorted(SHAPES)}, '
                             f'got {shape!r}')
        kind, count = SHAPES[shape]
        size = np.asarray(size, dtype=np.float64).ravel()
        if size.shape != (count,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
            raise ValueError(f'body {name}: a {shape} takes {count} positive size(s) (m), '
                             f'got {size.tolist()}')
        if not (np.isfinite(friction) and 0.0 <= friction <= 10.0):
            raise ValueError(f'body {name}: friction must be in [0, 10], got {friction}')
        padded = tuple(size.tolist()) + (0.0,) * (3 - count)
        self._bodies[name] = _Body(kind, padded, float(friction))

    def set_pose(self, name, rotation, translation):
        """
        Place body ``name`` where it is at the end of the next step.

        Checked before anything changes (unknown name: KeyError; a non-rotation or
        non-finite translation: ValueError). A body's first pose is also its start: it
        appears there without moving.
        """
        if name not in self._bodies:
            raise KeyError(f'no moving body named {name!r} (bodies: {self.names()})')
        rotation = check_rotation(rotation).copy()       # the caller may reuse its arrays
        translation = check_vector(translation, f'body {name} translation').copy()
        body = self._bodies[name]
        if body.rotation is None:
            body.start_rotation, body.start_translation = rotation, translation
        body.rotation, body.translation = rotation, translation
        self._packed = None

    def pose(self, name):
        """``(rotation, translation)`` body ``name`` will have after the next step, or None."""
        body = self._bodies[name]
        return None if body.rotation is None else (body.rotation, body.translation)

    def shape(self, name):
        """``(shape, size)`` of body ``name``, size as given to :meth:`add`."""
        body = self._bodies[name]
        shape = next(s for s, (kind, _) in SHAPES.items() if kind == body.kind)
        return shape, body.size[:SHAPES[shape][1]]

    def packed(self):
        """Return the placed bodies as the kernel reads them: float64 ``(n, ROW)``."""
        if self._packed is None:
            rows = [self._row(b) for b in self._bodies.values() if b.rotation is not None]
            self._packed = np.array(rows, dtype=np.float64).reshape(-1, layout.ROW)
        return self._packed

    @staticmethod
    def _row(body):
        row = np.empty(layout.ROW)
        row[layout.KIND], row[layout.FRICTION] = body.kind, body.friction
        row[layout.SIZE:layout.SIZE + 3] = body.size
        row[layout.R_END:layout.R_END + 9] = body.rotation.ravel()
        row[layout.T_END:layout.T_END + 3] = body.translation
        row[layout.R_START:layout.R_START + 9] = body.start_rotation.ravel()
        row[layout.T_START:layout.T_START + 3] = body.start_translation
        return row

    def plan(self):
        """Return ``{name: (start pose, end pose)}`` of the placed bodies (to split a step)."""
        return {name: ((b.start_rotation, b.start_translation), (b.rotation, b.translation))
                for name, b in self._bodies.items() if b.rotation is not None}

    def follow(self, plan, s):
        """Put each body of ``plan`` a fraction ``s`` of its way at the next step's end."""
        for name, (start, end) in plan.items():
            body = self._bodies[name]
            body.rotation, body.translation = part_way(start, end, s)
        self._packed = None

    def rewind(self, plan):
        """Undo the steps taken since ``plan``: each body starts and ends where it says."""
        for name, (start, end) in plan.items():
            body = self._bodies[name]
            (body.start_rotation, body.start_translation), (body.rotation, body.translation) \
                = start, end
        self._packed = None

    def commit(self):
        """
        Start the next step where every body is now, at rest.

        After a committed step (the next one starts where this one ended) and after a reset.
        """
        for body in self._bodies.values():
            if body.rotation is not None:
                body.start_rotation, body.start_translation = body.rotation, body.translation
        self._packed = None
