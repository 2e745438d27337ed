"""
Pure conversions between cloth arrays and ROS 2 messages (no node, no graph).

Kept apart from the node so they can be tested with plain pytest and reused by clients.
"""

import struct

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
import numpy as np
from rclpy.serialization import serialize_message
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
    A ``TRIANGLE_LIST`` marker of one mesh topology, kept serialised and refilled in place.

    ``Marker.points`` is a list of Python ``Point`` objects, which rclpy converts one
    attribute at a time when it publishes: 10 ms for the 65 x 65 level's 24,576 triangle
    corners here, and 1.7 ms more to write them, most of a 60 Hz tick (the node held 55-65 %
    of its ticks while a client had it show that level). This keeps the message's CDR bytes
    instead: a tick writes the corners' coordinates into them with one numpy gather, and
    the stamp; publishers and the bag send the bytes as they are (rclpy's ``publish``
    takes serialised messages). Each update returns its own copy, so a message being sent
    is never written.
    """

    # coordinates and a stamp no real message holds, to find where the CDR bytes keep them
    _STAMP = Time(sec=0x12345678, nanosec=0x1ABCDEF0)

    def __init__(self, triangles, frame_id, ns='cloth', marker_id=0,
                 rgba=(1.0, 0.55, 0.1, 1.0)):
        triangles = np.asarray(triangles)
        self.vertex_count = int(triangles.max()) + 1 if triangles.size else 0
        self._corners = triangles.ravel().astype(np.intp)
        msg = Marker()
        msg.header.frame_id = frame_id
        msg.header.stamp = self._STAMP
        msg.ns = ns
        msg.id = int(marker_id)
        msg.type = Marker.TRIANGLE_LIST
        msg.action = Marker.ADD
        msg.pose.orientation.w = 1.0
        msg.scale.x = msg.scale.y = msg.scale.z = 1.0
        msg.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                              a=float(rgba[3]))
        marks = np.arange(self._corners.size, dtype=np.float64)[:, None] + (0.25, 0.5, 0.75)
        msg.points = [Point(x=x, y=y, z=z) for x, y, z in marks.tolist()]
        self._data = bytearray(serialize_message(msg))
        self._stamp_at = _find(self._data, np.array([self._STAMP.sec, self._STAMP.nanosec],
                                                    dtype='<u4'))
        at = _find(self._data, marks.astype('<f8'))
        self._coordinates = np.frombuffer(self._data, dtype='<f8', count=marks.size,
                                          offset=at).reshape(-1, 3)

    def update(self, points, stamp):
        """Set the vertices to ``points`` (``(n, 3)`` metres, vertex order); return the bytes."""
        points = np.asarray(points, dtype=np.float64)
        if points.shape != (self.vertex_count, 3):
            raise ValueError(f'expected ({self.vertex_count}, 3) points, got {points.shape}')
        np.take(points, self._corners, axis=0, out=self._coordinates)
        struct.pack_into('<iI', self._data, self._stamp_at, stamp.sec, stamp.nanosec)
        return bytes(self._data)


def _find(data, values):
    """Return where ``values``' bytes lie in ``data`` (serialised message), or raise."""
    at = data.find(values.tobytes())
    if at < 0:
        raise RuntimeError('a serialised Marker does not hold its values as little-endian '
                           'CDR: this platform is not supported')
    return at
