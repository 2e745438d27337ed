"""
A stand-in robot that folds the cloth, using only sim_node's public topics.

It runs on the simulation's clock (``/clock``). It waits for ``cloth/points``, finds
the two corners nearest the viewer (smallest y, at the smallest and largest x), sends
grippers ``left`` and ``right`` there, closes them, carries the corners over the fold line
(the middle of the cloth along y) onto the far edge and lets go, then exits. The corners
travel on a half ellipse round the fold line, as wide as the near half is long and
``LIFT`` high, so they are never farther from the fold line than the cloth between
reaches: carried up and straight over, they pulled the whole cloth along (its far edge
1 m). The grippers turn with the cloth they hold, half a turn about x, as a hand folding
a towel does.
"""

import sys

from geometry_msgs.msg import PoseStamped
from hcloth_ros.ros_msgs import points_from_pointcloud2
import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Bool

# m: the half ellipse's height. Lower, the near edge sagged more between the grippers and
# landed short in the middle, pushing the crease off the middle (0.38: 2.9-3.0 cm; 0.42:
# 1.5-1.8 cm, far edge 0.0-0.2 cm, 0 below in 24 of 24 runs of tools/fold_jitter.py, the
# engine with the node's tick jitter); higher, the top layer landed stretched and sprang
# over the far edge on release, a corner tucking under it (0.46: 1 of 6 runs). Since the
# layer below carries the top one (self-contact's ``carry``, 2026-11-29) the top layer
# stays where it lands instead of creeping over the bottom one as it sank into it and
# was pushed out every step: its crease stayed at 2.7 cm from the middle with 0.42 and
# 2 cm short, where it had crept from 4.3 cm to 1.8 over the second after the landing;
# 0.45 and 1 cm short lay it 1.7-1.9 cm from the middle, 0 below, far edge 0.0 cm in 24
# of 24 runs
LIFT = 0.45
DURATION = 4.0      # s: from the start corner to the far edge
SHORT = 0.01        # m: the corners stop this short of the far edge
# m: and this far above where they started, about where the top layer comes to rest on
# the bottom one (the fold scene's 4 mm thickness): let go from 1 cm, the corners dropped
# onto the far ones and dragged them 1.8-2.0 cm (the node's demo; 1.6 cm from 5 mm)
ABOVE = 0.005


def fold_pose(start, far_y, t):
    """
    Return the gripper's pose at t s into the fold: offset from its start, quaternion (xyzw).

    Half an ellipse round the fold line ``(start y + far_y) / 2``: the angle goes from 0
    to pi with a smooth start and stop (1 - cos), and the gripper turns by it about -x, so
    the cloth it holds lies upside down on the far half at the end. Held without turning
    (translated only), the corner's patch ended pointing past the far edge: its points
    reached the ground beyond it and slid under the bottom layer's edge on release (1-2
    points below in 2 of 12 demo runs, 1 in 24 runs of tools/fold_jitter.py).
    """
    half = 0.5 * (far_y - start[1])
    s = np.clip(t / DURATION, 0.0, 1.0)
    angle = 0.5 * np.pi * (1.0 - np.cos(np.pi * s))
    reach = half - SHORT / 2
    offset = np.array([0.0, half - reach * np.cos(angle) - (half - reach),
                       LIFT * np.sin(angle) + ABOVE * s])
    return offset, (-np.sin(angle / 2), 0.0, 0.0, np.cos(angle / 2))


class FoldClient(Node):

    def __init__(self):
        # on the simulation's clock: the path is the same in simulated time however fast
        # the machine steps (on wall time a slow tick made the grippers jump ahead)
        super().__init__('hcloth_fold_client',
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
        self.pose_pubs = {n: self.create_publisher(PoseStamped, f'cloth/grippers/{n}/pose', 10)
                          for n in ('left', 'right')}
        self.close_pubs = {n: self.create_publisher(Bool, f'cloth/grippers/{n}/close', 10)
                           for n in ('left', 'right')}
        self.create_subscription(PointCloud2, 'cloth/points', self._on_cloud,
                                 qos_profile_sensor_data)
        self.starts = None
        self.t0 = None
        self.done = False
        self.create_timer(1 / 30, self._tick)

    def _on_cloud(self, msg):
        if self.starts is None:
            pts = points_from_pointcloud2(msg)
            self.frame_id = msg.header.frame_id
            self.starts = {'left': pts[np.argmin(pts[:, 0] + pts[:, 1])],
                           'right': pts[np.argmax(pts[:, 0] - pts[:, 1])]}
            self.far_y = pts[:, 1].max()
            self.get_logger().info(f'corners at {self.starts["left"].round(3).tolist()} and '
                                   f'{self.starts["right"].round(3).tolist()}')

    def _send(self, name, position, orientation=(0.0, 0.0, 0.0, 1.0)):
        msg = PoseStamped()
        msg.header.frame_id = self.frame_id
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, position)
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = map(float, orientation)
        self.pose_pubs[name].publish(msg)

    def _tick(self):
        if self.starts is None or self.done:
            return
        now = self.get_clock().now().nanoseconds * 1e-9     # simulated seconds
        if now == 0.0:
            return      # no /clock yet: a start at 0 would skip the path ahead later
        if self.t0 is None:
            self.t0 = now
            for name, start in self.starts.items():
                self._send(name, start)
            return
        t = now - self.t0
        if 0.3 <= t < 0.4:
            for pub in self.close_pubs.values():
                pub.publish(Bool(data=True))
        for name, start in self.starts.items():
            offset, orientation = fold_pose(start, self.far_y, t - 0.5)
            self._send(name, start + offset, orientation)
        if t > 4.7:
            for pub in self.close_pubs.values():
                pub.publish(Bool(data=False))
        if t > 6.0:
            self.get_logger().info('fold done')
            self.done = True


def main(args=None):
    rclpy.init(args=args)
    node = FoldClient()
    try:
        while rclpy.ok() and not node.done:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
