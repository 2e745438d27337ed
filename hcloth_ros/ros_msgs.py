"""
Pure conversions between cloth arrays and ROS 2 messages (no node, no graph).

Kept apart from the node so they can be tested with plain pytest and reused by clients.
"""

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

_XYZ_FIELDS = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
               for i, n in enumerate('xyz')]


def sim_stamp(seconds):
    """
    Return the ``builtin_interfaces/Time`` of ``seconds`` of simulated time.

    Rounded to the nanosecond from the float: 60 steps of 1/60 s stamp exactly 1 s.
    """
    ns = round(seconds * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def pointcloud2(points, frame_id, stamp):
    """
    Make an unorganised ``PointCloud2`` with float32 ``x y z`` fields from ``(n, 3)`` metres.

    ``data`` is assigned as ``bytes``: assigning a numpy array makes rclpy's setter walk it
    element by element (seconds for a large cloud).
    """
    xyz = np.ascontiguousarray(points, dtype='<f4')
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f'points must have shape (n, 3), got {xyz.shape}')
    msg = PointCloud2()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.height = 1
    msg.width = xyz.shape[0]
    msg.fields = _XYZ_FIELDS
    msg.is_bigendian = False
    msg.point_step = 12
    msg.row_step = 12 * xyz.shape[0]
    msg.is_dense = bool(np.all(np.isfinite(xyz)))
    msg.data = xyz.tobytes()
    return msg


def points_from_pointcloud2(msg):
    """
    Return the ``(n, 3)`` float64 positions of a cloud made by :func:`pointcloud2`.

    Any cloud whose first three fields are float32 x, y, z at offsets 0, 4, 8 reads too.
    """
    names = [(f.name, f.offset, f.datatype) for f in msg.fields[:3]]
    expected = [('x', 0, PointField.FLOAT32), ('y', 4, PointField.FLOAT32),
                ('z', 8, PointField.FLOAT32)]
    if names != expected or msg.is_bigendian:
        raise ValueError(f'expected little-endian float32 x, y, z at 0, 4, 8; got {names}')
    n = msg.width * msg.height
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(n, msg.point_step)
    return raw[:, :12].copy().view('<f4').reshape(n, 3).astype(np.float64)


class TriangleMarker:
    """
    A ``TRIANGLE_LIST`` marker of one mesh topology, refilled in place every tick.

    ``Marker.points`` is a list of Python ``Point`` objects: building them afresh cost
    about 6 ms for a 33 x 33 level here. This keeps one ``Point`` per vertex, which the
    list references once per triangle corner (three entries per triangle, as the message
    wants), so a tick only writes each vertex's coordinates: about 4x faster. The message
    is serialised when published, so reusing it for the next tick is safe.
    """

    def __init__(self, triangles, frame_id, ns='cloth', marker_id=0,
                 rgba=(1.0, 0.55, 0.1, 1.0)):
        triangles = np.asarray(triangles)
        self.vertex_count = int(triangles.max()) + 1 if triangles.size else 0
        self._vertices = [Point(check_fields=False) for _ in range(self.vertex_count)]
        msg = self.msg = Marker(check_fields=False)
        msg.header.frame_id = frame_id
        msg.ns = ns
        msg.id = int(marker_id)
        msg.type = Marker.TRIANGLE_LIST
        msg.action = Marker.ADD
        msg.pose.orientation.w = 1.0
        msg.scale.x = msg.scale.y = msg.scale.z = 1.0
        msg.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                              a=float(rgba[3]))
        msg.points = [self._vertices[i] for i in triangles.ravel().tolist()]

    def update(self, points, stamp):
        """Set the vertices to ``points`` (``(n, 3)`` metres, vertex order); return the marker."""
        points = np.asarray(points, dtype=np.float64)
        if points.shape != (self.vertex_count, 3):
            raise ValueError(f'expected ({self.vertex_count}, 3) points, got {points.shape}')
        for p, (x, y, z) in zip(self._vertices, points.tolist()):
            p.x, p.y, p.z = x, y, z
        self.msg.header.stamp = stamp
        return self.msg
