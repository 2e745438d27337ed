"""
The scene as a ``visualization_msgs/MarkerArray``: ground, boxes, spheres, moving obstacles.

Needs message types but no graph. The array starts with a DELETEALL of its namespace, so
an obstacle removed at runtime disappears from RViz; the node publishes it on a transient
local topic, so a viewer that starts late still gets the last one.
"""

from geometry_msgs.msg import Point, Quaternion
from hcloth_ros.core.poses import matrix_to_quaternion, rotation_between
import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

NS = 'hcloth_scene'
GROUND_SIZE = 10.0      # m: a ground plane is drawn as a square this wide
GROUND_THICKNESS = 0.001
STATIC = ColorRGBA(r=0.55, g=0.55, b=0.6, a=1.0)
GROUND = ColorRGBA(r=0.35, g=0.4, b=0.35, a=1.0)
MOVING = ColorRGBA(r=0.95, g=0.55, b=0.15, a=0.9)


def _marker(kind, frame_id, stamp, marker_id, centre, rotation, scale, color):
    m = Marker()
    m.header.frame_id, m.header.stamp = frame_id, stamp
    m.ns, m.id, m.type, m.action = NS, marker_id, kind, Marker.ADD
    m.pose.position = Point(x=float(centre[0]), y=float(centre[1]), z=float(centre[2]))
    x, y, z, w = matrix_to_quaternion(rotation)
    m.pose.orientation = Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))
    m.scale.x, m.scale.y, m.scale.z = (float(s) for s in scale)
    m.color = color
    return m


def _body_markers(shape, size, rotation, translation, first_id, frame_id, stamp):
    """Markers of one moving obstacle: a box, a sphere, or a capsule's cylinder and caps."""
    if shape == 'box':
        return [_marker(Marker.CUBE, frame_id, stamp, first_id, translation, rotation,
                        2 * np.asarray(size), MOVING)]
    radius = size[0]
    if shape == 'sphere':
        return [_marker(Marker.SPHERE, frame_id, stamp, first_id, translation, rotation,
                        [2 * radius] * 3, MOVING)]
    half = size[1]
    axis = rotation[:, 2]
    return [_marker(Marker.CYLINDER, frame_id, stamp, first_id, translation, rotation,
                    [2 * radius, 2 * radius, 2 * half], MOVING)] + [
        _marker(Marker.SPHERE, frame_id, stamp, first_id + 1 + i, translation + side * half * axis,
                rotation, [2 * radius] * 3, MOVING) for i, side in enumerate((-1, 1))]


def scene_markers(scene, bodies, frame_id, stamp):
    """
    Return the MarkerArray of a static ``scene`` (or None) and placed moving ``bodies``.

    Planes are thin squares ``GROUND_SIZE`` wide centred under the origin; obstacles are
    drawn at their true size (the margin the cloth keeps is not drawn).
    """
    clear = Marker()
    clear.header.frame_id, clear.header.stamp = frame_id, stamp
    clear.ns, clear.action = NS, Marker.DELETEALL
    markers = [clear]
    eye = np.eye(3)
    if scene is not None:
        for normal_offset in scene.planes:
            normal, offset = normal_offset[:3], normal_offset[3]
            centre = normal * (offset - GROUND_THICKNESS / 2)
            markers.append(_marker(Marker.CUBE, frame_id, stamp, len(markers), centre,
                                   rotation_between([0, 0, 1], normal),
                                   [GROUND_SIZE, GROUND_SIZE, GROUND_THICKNESS], GROUND))
        for box in scene.boxes:
            markers.append(_marker(Marker.CUBE, frame_id, stamp, len(markers), box[:3], eye,
                                   2 * box[3:], STATIC))
        for sphere in scene.spheres:
            markers.append(_marker(Marker.SPHERE, frame_id, stamp, len(markers), sphere[:3],
                                   eye, [2 * sphere[3]] * 3, STATIC))
    for name in bodies.names():
        pose = bodies.pose(name)
        if pose is not None:
            shape, size = bodies.shape(name)
            markers += _body_markers(shape, size, pose[0], pose[1], len(markers), frame_id,
                                     stamp)
    return MarkerArray(markers=markers)
