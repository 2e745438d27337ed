"""Checked poses: rotation matrices, vectors and quaternions from the outside world."""

import numpy as np


def check_rotation(rotation):
    """Return ``rotation`` as a float64 3x3 proper rotation; ValueError if it is not one."""
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError('rotation must be a finite 3x3 matrix')
    if np.max(np.abs(r @ r.T - np.eye(3))) > 1e-6 or np.linalg.det(r) < 0:
        raise ValueError('rotation must be orthonormal with determinant +1')
    return r


def check_vector(v, what):
    """Return ``v`` as 3 finite float64 numbers; ValueError naming ``what`` if not."""
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f'{what} must be 3 finite numbers, got {v!r}')
    return a


def quaternion_to_matrix(x, y, z, w):
    """Rotation matrix of a unit quaternion (normalised here; zero length refused)."""
    q = np.array([x, y, z, w], dtype=np.float64)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f'quaternion must be finite and non-zero, got {q.tolist()}')
    x, y, z, w = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quaternion(rotation):
    """Return the unit quaternion ``(x, y, z, w)`` of a rotation matrix (w >= 0)."""
    r = check_rotation(rotation)
    # Shepperd's method: divide by the largest of the four squared components
    trace = np.trace(r)
    squares = [trace, r[0, 0], r[1, 1], r[2, 2]]
    i = int(np.argmax(squares))
    if i == 0:
        w = np.sqrt(1.0 + trace) / 2
        q = [(r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w),
             (r[1, 0] - r[0, 1]) / (4 * w), w]
    else:
        j, k = (i % 3), ((i + 1) % 3)     # the other two axes after axis i - 1
        a = i - 1
        s = np.sqrt(1.0 + 2 * r[a, a] - trace) / 2
        q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / (4 * s)]
        q[a] = s
        q[j] = (r[j, a] + r[a, j]) / (4 * s)
        q[k] = (r[k, a] + r[a, k]) / (4 * s)
    q = np.array(q)
    return tuple(q if q[3] >= 0 else -q)


def slerp(r0, r1, s):
    """
    Return the rotation a fraction ``s`` of the way from ``r0`` to ``r1`` (the shorter arc).

    At a constant angular velocity: a grasp or a body whose pose is set once for several
    steps turns evenly over them. ``s`` = 1 returns ``r1`` itself (bit for bit).
    """
    if s >= 1.0:
        return r1
    q0 = np.array(matrix_to_quaternion(r0))
    q1 = np.array(matrix_to_quaternion(r1))
    c = float(q0 @ q1)
    if c < 0.0:             # q and -q are one rotation: take the shorter way
        q1, c = -q1, -c
    angle = np.arccos(min(c, 1.0))
    if angle < 1e-9:
        q = q0 + s * (q1 - q0)
    else:
        q = (np.sin((1.0 - s) * angle) * q0 + np.sin(s * angle) * q1) / np.sin(angle)
    return quaternion_to_matrix(*q)


def part_way(start, end, s):
    """
    Return the pose a fraction ``s`` of the way from ``start`` to ``end``.

    Each pose is ``(rotation, translation)``; the translation moves in a straight line
    and the rotation by :func:`slerp`. ``s`` = 1, or a pose that does not change,
    returns ``end``'s arrays themselves (a still grasp's targets stay bit for bit).
    """
    if s >= 1.0 or (np.array_equal(start[0], end[0]) and np.array_equal(start[1], end[1])):
        return end
    return slerp(start[0], end[0], s), start[1] + s * (end[1] - start[1])


def rotation_between(a, b):
    """Return the rotation matrix that turns unit vector a onto unit vector b (shortest)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-12:      # opposite: half a turn about any axis normal to a
        axis = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def pose_fields(rotation, translation):
    """Return a pose as plain lists, exactly (float64 to Python floats): JSON keeps them."""
    return (np.asarray(rotation, np.float64).tolist(),
            np.asarray(translation, np.float64).tolist())
