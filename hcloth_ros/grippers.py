"""
The node's grippers: newest command per gripper, applied to the cloth at a tick.

ROS-free (plain numbers in, log lines out), so it is tested without a graph. A flood of
commands keeps only the newest of each gripper; nothing is queued. A grasping gripper
moves towards its newest pose at most ``max_step`` a tick (the node's
``grasp_max_speed``): a pose far away is reached over several ticks, as a robot's
gripper would travel, instead of the grasped cloth being torn there in one step.
"""

from dataclasses import dataclass

from hcloth_ros.core.poses import part_way, pose_fields, quaternion_to_matrix
import numpy as np


@dataclass
class Gripper:
    """The newest command of one gripper."""

    name: str
    rotation: np.ndarray = None
    translation: np.ndarray = None
    pose_pending: bool = False
    close_request: bool = None      # None: nothing new; True: grasp; False: release
    grasping: bool = False
    sent: tuple = None              # the grasp frame's pose last sent to the cloth
    travelling: bool = False        # on its way to a pose farther than a tick's travel


def checked_pose(who, frame_id, expected_frame, position, orientation):
    """
    Return ``((rotation, translation), None)`` for a pose message's numbers.

    Or ``(None, (severity, why))`` when it must be dropped: ``'warning'`` for a wrong frame
    (there is no tf here), ``'error'`` for a non-finite position or a zero or non-finite
    quaternion. ``who`` names the sender in the message.
    """
    if frame_id != expected_frame:
        return None, ('warning', f'{who}: pose in frame {frame_id!r}, expected '
                                 f'{expected_frame!r} (no tf here): dropped')
    try:
        rotation = quaternion_to_matrix(*orientation)
        translation = np.array(position, dtype=np.float64)
        if translation.shape != (3,) or not np.all(np.isfinite(translation)):
            raise ValueError(f'position must be 3 finite numbers, got {translation.tolist()}')
    except ValueError as e:
        return None, ('error', f'{who}: bad pose dropped: {e}')
    return (rotation, translation), None


def travel(sent, target, max_step):
    """
    Return ``(pose, distance)``: where a frame at ``sent`` goes this tick towards ``target``.

    Poses are ``(rotation, translation)``. At most ``max_step`` (m; None: no limit) along
    the straight line, turning in proportion; ``target`` itself when it is that near (so
    ``pose is target`` says it arrived). ``distance``: from ``sent`` to ``target``.
    """
    distance = float(np.linalg.norm(target[1] - sent[1]))
    if max_step is None or distance <= max_step:
        return target, distance
    return part_way(sent, target, max_step / distance), distance


def far_warning(who, distance, max_step, parameter):
    """Return the log line of a pose farther than a tick's travel."""
    return ('warning', f'{who}: pose {distance:.3g} m away, more than {max_step:.3g} m a '
            f'tick ({parameter}): reached over {int(np.ceil(distance / max_step))} ticks')


def valid_name(name):
    """Whether ``name`` can name a gripper's topics (non-empty, no ``/``)."""
    return isinstance(name, str) and bool(name) and '/' not in name


class GripperBank:
    """
    Grippers by name.

    ``refused`` lists the names that cannot be used (empty, with a ``/``, or repeated).
    """

    def __init__(self, names):
        self.grippers = {}
        self.refused = []
        for name in names:
            if valid_name(name) and name not in self.grippers:
                self.grippers[name] = Gripper(name)
            else:
                self.refused.append(name)

    def __getitem__(self, name):
        return self.grippers[name]

    def __contains__(self, name):
        return name in self.grippers

    def __iter__(self):
        return iter(self.names())

    def names(self):
        return sorted(self.grippers)

    def set_pose(self, name, frame_id, expected_frame, position, orientation):
        """
        Take a target pose (``position`` xyz in m, ``orientation`` quaternion xyzw).

        Returns None if taken, else ``(severity, why)`` it was dropped (see
        :func:`checked_pose`); a dropped pose changes nothing.
        """
        pose, dropped = checked_pose(f'gripper {name}', frame_id, expected_frame, position,
                                     orientation)
        if dropped:
            return dropped
        g = self.grippers[name]
        (g.rotation, g.translation), g.pose_pending = pose, True
        return None

    def request_close(self, name, closed):
        """Ask for a grasp (``closed`` true) or a release at the next tick."""
        self.grippers[name].close_request = bool(closed)

    def apply(self, apply, points_near, max_step=None):
        """
        Turn the newest requests into simulation commands before a step.

        ``apply``: takes the commands (a :class:`~hcloth_ros.simulation.Simulation`'s);
        ``points_near(position)``: the point ids a gripper closing there takes;
        ``max_step``: the farthest a grasp frame's origin moves in one call (m; None: no
        limit), turning in proportion. Returns ``(severity, message)`` lines to log.
        """
        log = []
        for g in self.grippers.values():
            request, g.close_request = g.close_request, None
            if request and g.translation is None:
                log.append(('warning', f'gripper {g.name}: close before any pose: ignored'))
            elif request and not g.grasping:
                ids = points_near(g.translation)
                apply(['grasp', g.name, np.asarray(ids).tolist(),
                       *pose_fields(g.rotation, g.translation)])
                g.grasping, g.pose_pending = True, False
                g.sent, g.travelling = (g.rotation, g.translation), False
                log.append(('info', f'gripper {g.name}: grasped {len(ids)} points'))
            elif request is False and g.grasping:
                apply(['release', g.name])
                g.grasping = False
            if g.grasping and g.pose_pending:
                log += self._travel(g, apply, max_step)
        return log

    @staticmethod
    def _travel(g, apply, max_step):
        """Send gripper ``g`` towards its newest pose, at most ``max_step``; return log lines."""
        target = (g.rotation, g.translation)
        pose, distance = travel(g.sent, target, max_step)
        log = [] if pose is target or g.travelling else \
            [far_warning(f'gripper {g.name}', distance, max_step, 'grasp_max_speed')]
        g.travelling = pose is not target
        apply(['move', g.name, *pose_fields(*pose)])
        g.sent, g.pose_pending = pose, g.travelling
        return log

    def forget_grasps(self):
        """After a reset: nothing held, no command pending (poses are kept)."""
        for g in self.grippers.values():
            g.grasping, g.close_request, g.pose_pending = False, None, False
            g.travelling = False


def points_within(points, position, radius):
    """
    Return the indices of ``points`` ``(n, 3)`` within ``radius`` of ``position``.

    If none is that close, the nearest one.
    """
    d = np.linalg.norm(points - position, axis=1)
    ids = np.flatnonzero(d <= radius)
    return ids if ids.size else np.array([int(np.argmin(d))])
