"""
The node's moving obstacles: declared by ``scene.moving_obstacles``, newest pose per tick.

ROS-free (strings and numbers in, log lines out), tested without a graph. Each obstacle
is one string ``'<name> <shape> <sizes...> [friction]'``: ``box`` takes three half
extents, ``sphere`` a radius, ``capsule`` a radius and a half length along its z axis
(m); a number after the sizes is its friction coefficient (default ``scene.friction``).
A flood of poses keeps only the newest of each obstacle; nothing is queued. A placed
obstacle travels to its newest pose at most ``max_step`` a tick (the node's
``obstacle_max_speed``), as grippers do.
"""

import re

from hcloth_ros.core.bodies import MAX_BODIES, SHAPES
from hcloth_ros.core.poses import pose_fields
from hcloth_ros.grippers import checked_pose, far_warning, travel

# a name must make a valid topic token: cloth/obstacles/<name>/pose
NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*$')


def parse_spec(text, default_friction):
    """
    Return ``(name, shape, sizes, friction)`` of one obstacle string.

    ValueError naming the string and what is allowed when it is not one.
    """
    words = str(text).split()
    usage = (f'moving obstacle {text!r}: expected "<name> <shape> <sizes> [friction]" with '
             'a name of letters, digits and _ starting with a letter, shape box (3 half '
             'extents), sphere (radius) or capsule (radius, half length), sizes in m and '
             'positive, friction in [0, 10]')
    if len(words) < 3 or not NAME.match(words[0]) or words[1] not in SHAPES:
        raise ValueError(usage)
    name, shape, numbers = words[0], words[1], words[2:]
    count = SHAPES[shape][1]
    if len(numbers) not in (count, count + 1):
        raise ValueError(usage)
    try:
        values = [float(w) for w in numbers]
    except ValueError:
        raise ValueError(usage) from None
    friction = values[count] if len(values) > count else float(default_friction)
    if not all(0 < v < float('inf') for v in values[:count]) or not 0 <= friction <= 10:
        raise ValueError(usage)
    return name, shape, values[:count], friction


class ObstacleBank:
    """
    The node's moving obstacles, added to ``bodies`` (a control's ``MovingBodies``).

    ``specs``: the parameter's strings (``['']``: none). Raises ValueError before adding
    anything if one is malformed, repeated or out of range.
    """

    def __init__(self, specs, bodies, default_friction):
        parsed = [parse_spec(s, default_friction) for s in specs if str(s).strip()]
        names = [p[0] for p in parsed]
        if len(set(names)) != len(names):
            raise ValueError(f'moving obstacle names repeat: {sorted(names)}')
        if len(parsed) > MAX_BODIES:
            raise ValueError(f'at most {MAX_BODIES} moving obstacles, got {len(parsed)}')
        for name, shape, sizes, friction in parsed:
            bodies.add(name, shape, sizes, friction)
        self.bodies = bodies
        self._pending = {}
        self._travelling = set()     # names on their way to a pose beyond a tick's travel

    def names(self):
        return self.bodies.names()

    def __contains__(self, name):
        return name in self.bodies

    def set_pose(self, name, frame_id, expected_frame, position, orientation):
        """
        Keep obstacle ``name``'s newest pose (``position`` xyz, ``orientation`` xyzw).

        Returns None if kept, else ``(severity, why)`` it was dropped (see
        :func:`~hcloth_ros.grippers.checked_pose`); a dropped pose changes nothing.
        """
        pose, dropped = checked_pose(f'obstacle {name}', frame_id, expected_frame, position,
                                     orientation)
        if dropped:
            return dropped
        self._pending[name] = pose
        return None

    def apply(self, apply, max_step=None):
        """
        Place every obstacle with a new pose for the next step; return ``(moved, log)``.

        ``apply``: takes the commands (a :class:`~hcloth_ros.simulation.Simulation`'s);
        ``max_step``: the farthest a placed obstacle moves in one call (m; None: no limit;
        its first pose places it at once); ``log``: ``(severity, message)`` lines.
        """
        pending, self._pending, log = self._pending, {}, []
        for name, target in pending.items():
            sent = self.bodies.pose(name)
            pose, distance = (target, 0.0) if sent is None else travel(sent, target,
                                                                       max_step)
            if pose is not target:
                if name not in self._travelling:
                    log.append(far_warning(f'obstacle {name}', distance, max_step,
                                           'obstacle_max_speed'))
                self._travelling.add(name)
                self._pending.setdefault(name, target)     # unless a newer one came
            else:
                self._travelling.discard(name)
            apply(['body', name, *pose_fields(*pose)])
        return bool(pending), log
