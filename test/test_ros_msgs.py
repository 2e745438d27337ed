"""Message conversions, without a ROS graph."""

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from hcloth_ros.core import ClothBuilder, State
from hcloth_ros.ros_msgs import pointcloud2, points_from_pointcloud2, TriangleMarker
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker


def test_pointcloud2_round_trip_is_float32_exact():
    # float32 fields: the round trip equals the float32 rounding of the input exactly
    rng = np.random.default_rng(1)
    pts = rng.normal(0, 2, (1000, 3))
    msg = pointcloud2(pts, 'world', Time(sec=3, nanosec=7))
    assert (msg.width, msg.height, msg.point_step, msg.row_step) == (1000, 1, 12, 12000)
    assert [f.name for f in msg.fields] == ['x', 'y', 'z']
    assert msg.header.frame_id == 'world' and msg.header.stamp.sec == 3
    assert msg.is_dense and len(msg.data) == 12000
    back = points_from_pointcloud2(msg)
    assert np.array_equal(back, pts.astype(np.float32).astype(np.float64))


def test_pointcloud2_flags_non_finite_and_refuses_bad_shapes():
    pts = np.zeros((4, 3))
    pts[2, 1] = np.nan
    assert not pointcloud2(pts, 'world', Time()).is_dense
    with pytest.raises(ValueError, match=r'\(n, 3\)'):
        pointcloud2(np.zeros((4, 2)), 'world', Time())


def test_triangle_marker_of_a_level_has_three_points_per_triangle():
    model = ClothBuilder(resolution=(3, 4), level_count=2).finalize()
    state = State.at_rest(model)
    tri = model.grid_triangles(1)
    marker = TriangleMarker(tri, 'world', ns='lod', marker_id=1)
    msg = deserialize_message(marker.update(state.points(1), Time(sec=3, nanosec=5)), Marker)
    assert msg.type == Marker.TRIANGLE_LIST and msg.ns == 'lod' and msg.id == 1
    assert msg.header.frame_id == 'world' and msg.header.stamp == Time(sec=3, nanosec=5)
    assert msg.action == Marker.ADD and msg.pose.orientation.w == 1.0 and msg.color.a == 1.0
    # level 1 of a 3 x 4 level 0 is 7 x 5 points: 2 * 6 * 4 triangles
    assert len(msg.points) == 3 * 2 * 6 * 4 == 3 * len(tri)
    corners = np.array([[p.x, p.y, p.z] for p in msg.points])
    assert np.array_equal(corners, state.points(1)[tri.ravel()])
    # refilled in place: the next tick's positions replace every corner; the bytes sent
    # before stay as they were
    first = marker.update(state.points(1), Time(sec=3))
    moved = state.points(1) + [0.0, 0.0, -0.25]
    msg = deserialize_message(marker.update(moved, Time(sec=4)), Marker)
    corners = np.array([[p.x, p.y, p.z] for p in msg.points])
    assert np.array_equal(corners, moved[tri.ravel()]) and msg.header.stamp.sec == 4
    kept = np.array([[p.x, p.y, p.z] for p in deserialize_message(first, Marker).points])
    assert np.array_equal(kept, state.points(1)[tri.ravel()])
    with pytest.raises(ValueError, match=r'\(35, 3\)'):
        marker.update(state.points(0), Time())


def test_triangle_marker_bytes_are_what_rclpy_serialises():
    # the same message built point by point, as the node did before it kept the bytes
    model = ClothBuilder(resolution=(5, 5), level_count=2).finalize()
    points = State.at_rest(model).points(1) + np.random.default_rng(0).normal(0, 0.1, (81, 3))
    tri = model.grid_triangles(1)
    msg = Marker(ns='hcloth_lod', id=0, type=Marker.TRIANGLE_LIST, action=Marker.ADD)
    msg.header.frame_id, msg.header.stamp = 'map', Time(sec=12, nanosec=345)
    msg.pose.orientation.w = 1.0
    msg.scale.x = msg.scale.y = msg.scale.z = 1.0
    msg.color = ColorRGBA(r=1.0, g=0.55, b=0.1, a=1.0)
    msg.points = [Point(x=x, y=y, z=z) for x, y, z in points[tri.ravel()].tolist()]
    marker = TriangleMarker(tri, 'map', ns='hcloth_lod')
    data = marker.update(points, Time(sec=12, nanosec=345))
    # equal field for field (the bytes may differ where CDR pads: rclpy leaves padding as
    # it finds it; both read back, as the colour is float32 on the wire)
    reference = serialize_message(msg)
    assert len(data) == len(reference)
    assert deserialize_message(data, Marker) == deserialize_message(reference, Marker)
