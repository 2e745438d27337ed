"""
A stand-in robot that folds the cloth, using only sim_node's public topics.

It waits for ``cloth/points``, finds the two corners nearest the viewer (smallest y, at the
smallest and largest x), sends grippers ``left`` and ``right`` there, closes them, lifts
0.25 m, carries the corners over to the far edge, lowers them and lets go, then exits.
"""

import sys

from geometry_msgs.msg import PoseStamped
from hcloth_ros.ros_msgs import points_from_pointcloud2
import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Bool

LIFT = 0.25


def waypoints(start, far_y):
    """(time s, offset from the start corner) of the folding motion, piecewise linear."""
    over = np.array([0.0, far_y - start[1], 0.0])
    return [(0.0, np.zeros(3)), (1.0, np.array([0.0, 0.0, LIFT])),
            (3.0, over + [0.0, 0.0, LIFT]), (4.0, over + [0.0, 0.0, 0.02])]


def interpolate(plan, t):
    times = [p[0] for p in plan]
    offsets = np.array([p[1] for p in plan])
    return np.array([np.interp(t, times, offsets[:, d]) for d in range(3)])


class FoldClient(Node):

    def __init__(self):
        super().__init__('hcloth_fold_client')
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

    def _send(self, name, position):
        msg = PoseStamped()
        msg.header.frame_id = self.frame_id
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, position)
        msg.pose.orientation.w = 1.0
        self.pose_pubs[name].publish(msg)

    def _tick(self):
        if self.starts is None or self.done:
            return
        now = self.get_clock().now().nanoseconds * 1e-9
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
            self._send(name, start + interpolate(waypoints(start, self.far_y), t - 0.5))
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
