"""
What the LOD marker costs a tick per level: kept as bytes, and as ``Point`` objects.

    .venv/bin/python tools/marker_cost.py [--repeats 20]

For each level of the node's default scene, the median time to write a tick's positions
into the marker and to publish it (no subscriber: the conversion and the middleware's
copy), both for :class:`~hcloth_ros.ros_msgs.TriangleMarker` (serialised bytes) and for
a ``Marker`` whose ``Point`` objects are kept and refilled, as the node did before.
"""

import argparse
import time

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from hcloth_ros import params
from hcloth_ros.ros_msgs import TriangleMarker
import numpy as np
import rclpy
from visualization_msgs.msg import Marker


class PointMarker:
    """The marker as the node kept it before: one ``Point`` per vertex, refilled."""

    def __init__(self, triangles):
        count = int(triangles.max()) + 1
        self._vertices = [Point() for _ in range(count)]
        self.msg = Marker(type=Marker.TRIANGLE_LIST)
        self.msg.points = [self._vertices[i] for i in triangles.ravel().tolist()]

    def update(self, points, stamp):
        for p, (x, y, z) in zip(self._vertices, points.tolist()):
            p.x, p.y, p.z = x, y, z
        self.msg.header.stamp = stamp
        return self.msg


def median_ms(marker, points, publisher, repeats):
    """Median milliseconds of ``update`` and of ``publish`` over ``repeats`` ticks."""
    write, send = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        msg = marker.update(points, Time())
        middle = time.perf_counter()
        publisher.publish(msg)
        write.append(middle - start)
        send.append(time.perf_counter() - middle)
    return 1e3 * np.median(write), 1e3 * np.median(send)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--repeats', type=int, default=20)
    args = parser.parse_args(argv)
    rclpy.init()
    node = rclpy.create_node('marker_cost')
    publisher = node.create_publisher(Marker, 'marker_cost', 1)
    model, _, state, _ = params.build_all(params.resolve({}))
    print('level  points  bytes: write / publish (ms)  Point objects: write / publish (ms)')
    for level in range(model.level_count):
        triangles = np.asarray(model.grid_triangles(level))
        points = state.points(level)
        kept = median_ms(TriangleMarker(triangles, 'world'), points, publisher, args.repeats)
        old = median_ms(PointMarker(triangles), points, publisher, args.repeats)
        print(f'{level:5d} {len(points):7d}  {kept[0]:13.2f} / {kept[1]:.2f}'
              f'  {old[0]:22.2f} / {old[1]:.2f}')
    node.destroy_node()
    rclpy.shutdown()


if __name__ == '__main__':
    main()
