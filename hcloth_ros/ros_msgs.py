"""Pure conversions between cloth arrays and ROS 2 messages (no node, no graph).

Kept apart from the node so they can be tested with plain pytest and reused by clients.
"""

import numpy as np
from geometry_msgs.msg import Point
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

_XYZ_FIELDS = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
               for i, n in enumerate('xyz')]


def pointcloud2(points, frame_id, stamp):
    """An unorganised ``PointCloud2`` with float32 ``x y z`` fields from ``(n, 3)`` metres.

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
    """``(n, 3)`` float64 positions of a cloud made by :func:`pointcloud2` (or any cloud
    whose first three fields are float32 x, y, z at offsets 0, 4, 8)."""
    names = [(f.name, f.offset, f.datatype) for f in msg.fields[:3]]
    expected = [('x', 0, PointField.FLOAT32), ('y', 4, PointField.FLOAT32),
                ('z', 8, PointField.FLOAT32)]
    if names != expected or msg.is_bigendian:
        raise ValueError(f'expected little-endian float32 x, y, z at 0, 4, 8; got {names}')
    n = msg.width * msg.height
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(n, msg.point_step)
    return raw[:, :12].copy().view('<f4').reshape(n, 3).astype(np.float64)


def triangle_marker(points, triangles, frame_id, stamp, ns='cloth', marker_id=0,
                    rgba=(1.0, 0.55, 0.1, 1.0)):
    """A ``TRIANGLE_LIST`` marker: three ``points`` entries per triangle (metres).

    ``Marker.points`` is a list of Python ``Point`` objects, which costs about a
    microsecond each to build: meant for the coarse levels a viewer shows, not for the
    finest mesh (that goes out as a ``PointCloud2``).
    """
    corners = np.asarray(points, dtype=np.float64)[np.asarray(triangles).ravel()]
    msg = Marker()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.ns = ns
    msg.id = int(marker_id)
    msg.type = Marker.TRIANGLE_LIST
    msg.action = Marker.ADD
    msg.pose.orientation.w = 1.0
    msg.scale.x = msg.scale.y = msg.scale.z = 1.0
    msg.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                          a=float(rgba[3]))
    msg.points = [Point(x=x, y=y, z=z) for x, y, z in corners.tolist()]
    return msg
