"""
A thin Rerun logger: the cloth and its metrics on a ``sim_time`` timeline.

Entities: ``cloth/finest`` (mesh of the finest simulated level, every
``finest_every``-th step), ``cloth/lod`` (mesh of the LOD level, every step),
``cloth/pins`` and ``cloth/grasps`` (held points of the finest level), ``scene/*`` (the
ground, boxes and spheres when they change, the moving obstacles when they move) and
``metrics/*`` scalars: ``step_ms``, ``real_time_factor``, ``levels``, ``max_strain``,
``energy``. The file is flushed every ``flush_period`` seconds so a crash loses at most
that much, and :meth:`close` flushes and finishes it (footer included).

The finest mesh is shaded (vertex normals) and drawn on both faces, coloured from one edge
of the cloth to the other (blue at v = 0 to orange at v = 1 of its rest rectangle), so a
folded cloth shows which part lies on which.
"""

import time

from hcloth_ros.core.metrics import energy
from hcloth_ros.core.poses import matrix_to_quaternion, rotation_between
import numpy as np
import rerun as rr
import rerun.blueprint as rrb


METRICS = (('step_ms', 'step time (ms)'), ('real_time_factor', 'real-time factor'),
           ('levels', 'levels simulated'), ('max_strain', 'largest strain'),
           ('energy', 'energy (J)'))


def _blueprint():
    """
    Lay out the viewer: the finest mesh and the LOD mesh side by side, the plots beside.

    Held points show in both meshes; one plot per metric (their units differ); the
    ``sim_time`` timeline selected.
    """
    held = ['+ /cloth/pins', '+ /cloth/grasps', '+ /scene/**']
    meshes = rrb.Vertical(
        rrb.Spatial3DView(origin='/', name='finest level',
                          contents=['+ /cloth/finest'] + held),
        rrb.Spatial3DView(origin='/', name='LOD marker level', contents=['+ /cloth/lod'] + held))
    plots = rrb.Vertical(*(rrb.TimeSeriesView(origin=f'/metrics/{name}', name=title)
                           for name, title in METRICS))
    return rrb.Blueprint(rrb.Horizontal(meshes, plots, column_shares=[3, 2]),
                         rrb.TimePanel(timeline='sim_time'), collapse_panels=True)


GROUND_SCALE = 3.0     # a plane is drawn as a square this many cloth sizes wide ...
GROUND_DROP = 0.005    # m: ... this far below its surface: 2 mm above it (the margin), a
# cloth lying on it was hidden by the viewer's depth precision
GROUND_COLOUR = 0x6E8C6EFF
STATIC_COLOUR = 0x9A9AA6FF
MOVING_COLOUR = 0xF08C28E6
EDGE_V0 = np.array([60, 110, 220, 255])     # the cloth's colour at v = 0 ...
EDGE_V1 = np.array([240, 150, 40, 255])     # ... and at v = 1


def grid_normals(q):
    """Return unit vertex normals ``(n, 3)`` float32 of a grid level ``(3, rows, cols)``."""
    along_u = np.gradient(q, axis=2)
    along_v = np.gradient(q, axis=1)
    n = np.cross(along_u, along_v, axis=0).reshape(3, -1).T
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


def _quaternion_from_z(normal):
    """Quaternion (xyzw) turning +z onto ``normal``."""
    return matrix_to_quaternion(rotation_between([0.0, 0.0, 1.0], normal))


class Recorder:
    """Records one run to ``path`` (an ``.rrd`` file) or streams it to ``url``."""

    def __init__(self, model, path='', url='', finest_every=1, flush_period=2.0):
        if not path and not url:
            raise ValueError('Recorder needs a file path or a viewer url')
        self.model = model
        self.finest_every = max(1, int(finest_every))
        self.flush_period = float(flush_period)
        self.rec = rr.RecordingStream('hcloth_ros')
        rr.set_log_time_enabled(False, recording=self.rec)   # deterministic files
        if url:
            self.rec.connect_grpc(url, default_blueprint=_blueprint())
        else:
            self.rec.save(path, default_blueprint=_blueprint())
        self.rec.log('/', rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._topology = {}
        self._last_flush = time.monotonic()
        self._steps = 0

    def _mesh(self, entity, state, k, colour, shaded=False):
        if self._topology.get(entity) != k:
            # topology changes with the level: logged on the timeline, not static
            lv = self.model.level(k)
            extra = {}
            if shaded:
                v = np.repeat(np.linspace(0.0, 1.0, lv.rows), lv.cols)[:, None]
                extra = {'vertex_colors': ((1 - v) * EDGE_V0 + v * EDGE_V1).astype(np.uint8),
                         'face_rendering': rr.components.MeshFaceRendering.DoubleSided}
            self.rec.log(entity, rr.Mesh3D.from_fields(
                triangle_indices=self.model.grid_triangles(k).astype(np.uint32),
                albedo_factor=colour, **extra))
            self._topology[entity] = k
        q = state.q[k]
        fields = {'vertex_positions': q.reshape(3, -1).T.astype(np.float32)}
        if shaded:
            fields['vertex_normals'] = grid_normals(q)
        self.rec.log(entity, rr.Mesh3D.from_fields(**fields))

    def log_obstacles(self, scene, sim_time):
        """
        Log the static obstacles (``scene``, or None) at ``sim_time`` (s).

        On the timeline, not static: ``scene.*`` parameters change at runtime. The node
        calls it at start and when the scene changes.
        """
        self.rec.set_time('sim_time', duration=sim_time)
        planes = [] if scene is None else scene.planes
        boxes = np.zeros((0, 6)) if scene is None else scene.boxes
        spheres = np.zeros((0, 4)) if scene is None else scene.spheres
        # a plane: a thin square under where the cloth started, its top GROUND_DROP below
        middle = self.model.rest_positions(0).reshape(3, -1).mean(axis=1)
        half = GROUND_SCALE * max(self.model.width, self.model.height) / 2
        self.rec.log('scene/ground', rr.Boxes3D(
            centers=[middle - (middle @ p[:3] - p[3] + GROUND_DROP + 0.0005) * p[:3]
                     for p in planes],
            half_sizes=[(half, half, 0.0005)] * len(planes),
            quaternions=[_quaternion_from_z(p[:3]) for p in planes], colors=GROUND_COLOUR,
            fill_mode='solid'))
        self.rec.log('scene/boxes', rr.Boxes3D(centers=boxes[:, :3], half_sizes=boxes[:, 3:],
                                               colors=STATIC_COLOUR, fill_mode='solid'))
        self.rec.log('scene/spheres', rr.Ellipsoids3D(
            centers=spheres[:, :3], half_sizes=np.repeat(spheres[:, 3:], 3, axis=1),
            colors=STATIC_COLOUR, fill_mode='solid'))

    def log_bodies(self, bodies, sim_time):
        """Log the placed moving ``bodies`` at ``sim_time`` (s): at start and when one moves."""
        self.rec.set_time('sim_time', duration=sim_time)
        placed = {'box': [], 'sphere': [], 'capsule': []}
        for name in bodies.names():
            if bodies.pose(name) is not None:
                shape, size = bodies.shape(name)
                placed[shape].append((name, size) + bodies.pose(name))
        self.rec.log('scene/moving/boxes', rr.Boxes3D(
            centers=[p[3] for p in placed['box']], half_sizes=[p[1] for p in placed['box']],
            quaternions=[matrix_to_quaternion(p[2]) for p in placed['box']],
            labels=[p[0] for p in placed['box']], colors=MOVING_COLOUR, fill_mode='solid'))
        self.rec.log('scene/moving/spheres', rr.Ellipsoids3D(
            centers=[p[3] for p in placed['sphere']],
            half_sizes=[[p[1][0]] * 3 for p in placed['sphere']],
            labels=[p[0] for p in placed['sphere']], colors=MOVING_COLOUR, fill_mode='solid'))
        # a capsule's segment runs from its translation along its z: start at one cap
        self.rec.log('scene/moving/capsules', rr.Capsules3D(
            lengths=[2 * p[1][1] for p in placed['capsule']],
            radii=[p[1][0] for p in placed['capsule']],
            translations=[p[3] - p[1][1] * p[2][:, 2] for p in placed['capsule']],
            quaternions=[matrix_to_quaternion(p[2]) for p in placed['capsule']],
            labels=[p[0] for p in placed['capsule']], colors=MOVING_COLOUR,
            fill_mode='solid'))

    def log_step(self, state, finest, lod, report, wall_seconds, simulated_seconds,
                 held=None):
        """Log the state after a tick: meshes, held points and per-step metrics."""
        self.rec.set_time('sim_time', duration=state.time)
        self.rec.set_time('step', sequence=self._steps)
        if self._steps % self.finest_every == 0:
            self._mesh('cloth/finest', state, finest, 0xFFFFFFFF, shaded=True)
        self._mesh('cloth/lod', state, lod, 0x3C8CDC80)
        for name, points in (held or {}).items():
            self.rec.log(f'cloth/{name}', rr.Points3D(points, radii=0.01))
        kin, pot, ela = energy(self.model, state, finest)
        rtf = simulated_seconds / wall_seconds if wall_seconds > 0 else 0.0
        values = {'step_ms': report.seconds * 1e3, 'real_time_factor': rtf,
                  'levels': len(report.levels), 'max_strain': report.max_strain,
                  'energy': kin + pot + ela}
        for name, _ in METRICS:
            self.rec.log(f'metrics/{name}', rr.Scalars(float(values[name])))
        self._steps += 1
        if time.monotonic() - self._last_flush > self.flush_period:
            self.rec.flush()
            self._last_flush = time.monotonic()

    def close(self):
        """Flush everything and finish the file (footer): readable after any stop."""
        self.rec.flush()
        self.rec.disconnect()
