"""
A thin Rerun logger: the cloth and its metrics on a ``sim_time`` timeline.

Entities: ``cloth/finest`` (mesh of the finest simulated level, every
``finest_every``-th step), ``cloth/lod`` (mesh of the LOD level, every step),
``cloth/pins`` and ``cloth/grasps`` (held points of the finest level, when they change),
``scene/*`` (the ground, boxes and spheres when they change, the moving obstacles when they
move) and ``metrics/*`` scalars (:data:`METRICS`), one per step unless said otherwise:

* ``step_ms``: the compute of the tick's steps, in ms (its report's ``seconds``: the
  substeps and every try of a retried step, :func:`~hcloth_ros.core.solvers.merged`);
* ``headroom``: simulated seconds per second of the tick's compute, ``simulated_seconds /
  wall_seconds`` as passed in (the node: its tick up to the recorder): above 1 the step
  is faster than real time (2: it could run twice as fast), below 1 a node paced at real
  time cannot keep up (no value for a ``wall_seconds`` of 0);
* ``real_time_factor``: simulated seconds advanced per wall-clock second
  (``time.monotonic()``) between this ``log_step`` call and the previous one: 1.0 when
  the node keeps real time, whatever its headroom (a pause shows as one low value). The
  first call has no previous one and logs no value;
* ``levels``, ``energy``; ``max_strain``: the largest finest strain after any of the
  tick's steps (its report's ``peak_strain``: a strain reached at a substep or a retry's
  smaller step and undone by the tick's end shows), or the strain that got its last step
  refused if that is larger (the refused state itself is not kept).

For exact replay (:mod:`hcloth_ros.replay`): ``replay/start`` (static, a JSON text: what
builds the simulation again, :meth:`~hcloth_ros.simulation.Simulation.start_record`) and
``replay/commands`` (a JSON text log: the commands applied before a step, on that step's
``step``). The ``step`` timeline counts the logged steps from 0, across resets.

The file is flushed every ``flush_period`` seconds (of wall time, at the first step after
it) so a crash loses about that much, and :meth:`close` flushes and finishes it (footer
included). The default, 1.5 s, keeps a SIGKILL's loss under issue 12's 2 s: at 2.0 the
stress suite's kills lost 2.00-2.02 s now and then (a flush falls at the first step after
the period, and a kill just before it).

The finest mesh is shaded (vertex normals) and drawn on both faces, coloured from one edge
of the cloth to the other (blue at v = 0 to orange at v = 1 of its rest rectangle), so a
folded cloth shows which part lies on which.

Size (``tools/recording_size.py``): a step's mesh is sent as a partial update of vertex
positions (and normals for the finest) only; triangle indices, vertex colours, face
rendering and albedo are logged once per level a mesh shows, on the timeline (a level can
change, so they are not static) and found from later steps by latest-at. Normals are
rounded to 1/64 (under a degree, invisible in the shading), which lets the file's LZ4
compress them about threefold; positions are float32 as simulated. A file's rows are
batched ``flush_period`` at a time, one chunk (with its schema) per entity.
"""

import json
import time

from hcloth_ros.core.metrics import energy
from hcloth_ros.core.poses import matrix_to_quaternion, rotation_between
import numpy as np
import rerun as rr
import rerun.blueprint as rrb


METRICS = (('step_ms', 'step time (ms)'),
           ('headroom', 'headroom (simulated s per compute s)'),
           ('real_time_factor', 'real-time factor (simulated s per wall s)'),
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


NORMAL_STEP = 1 / 64     # normals are rounded to this: see the module docstring


def grid_normals(q):
    """Return unit vertex normals ``(n, 3)`` float32 of a grid level ``(3, rows, cols)``."""
    along_u = np.gradient(q, axis=2)
    along_v = np.gradient(q, axis=1)
    n = np.cross(along_u, along_v, axis=0).reshape(3, -1).T
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)


def rounded_normals(normals):
    """
    Round unit normals to multiples of :data:`NORMAL_STEP` (float32, exactly representable).

    Neighbouring vertices of a smooth cloth then share bit patterns LZ4 finds, where full
    precision floats do not compress at all; a unit vector's largest component is at
    least 0.57, so none rounds to zero (no normal: the viewer would not shade it).
    """
    return (np.round(normals / NORMAL_STEP) * NORMAL_STEP).astype(np.float32)


def _quaternion_from_z(normal):
    """Quaternion (xyzw) turning +z onto ``normal``."""
    return matrix_to_quaternion(rotation_between([0.0, 0.0, 1.0], normal))


class Recorder:
    """Records one run to ``path`` (an ``.rrd`` file) or streams it to ``url``."""

    def __init__(self, model, path='', url='', finest_every=1, flush_period=1.5):
        if not path and not url:
            raise ValueError('Recorder needs a file path or a viewer url')
        self.model = model
        self.finest_every = max(1, int(finest_every))
        self.flush_period = float(flush_period)
        self.rec = rr.RecordingStream('hcloth_ros', batcher_config=self._batching(url))
        rr.set_log_time_enabled(False, recording=self.rec)   # deterministic files
        if url:
            self.rec.connect_grpc(url, default_blueprint=_blueprint())
        else:
            self.rec.save(path, default_blueprint=_blueprint())
        self.rec.log('/', rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._topology = {}
        self._held = {}
        self._last_flush = time.monotonic()
        self._last_call = None
        self._steps = 0

    def _batching(self, url):
        """
        Return the chunk batcher's settings: rows of ``flush_period`` per chunk in a file.

        Every chunk repeats its entity's schema: rerun's default 0.2 s batches cost 0.04 MB
        more per simulated second at the default scene, a tenth of the file with the finest
        mesh every 30th step. A crash loses no more than the explicit flush every
        ``flush_period`` already allows. A viewer gets the default: live data should show
        within a fraction of a second.
        """
        if url:
            return None
        return rr.ChunkBatcherConfig(flush_tick=self.flush_period)

    def _mesh(self, entity, state, k, colour, shaded=False):
        """Log level k's mesh: what the level fixes once per level, then positions (normals)."""
        if self._topology.get(entity) != k:
            self._log_topology(entity, k, colour, shaded)
        q = state.q[k]
        fields = {'vertex_positions': q.reshape(3, -1).T.astype(np.float32)}
        if shaded:
            fields['vertex_normals'] = rounded_normals(grid_normals(q))
        self.rec.log(entity, rr.Mesh3D.from_fields(**fields))

    def _log_topology(self, entity, k, colour, shaded):
        """
        Log what level k fixes of a mesh: triangles, albedo (and colours, both faces).

        On the timeline, not static: the level an entity shows changes (the governor,
        ``lod_level``), and a static topology would pair every earlier step's positions
        with the new level's triangles. Later steps find it by latest-at.
        """
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

    def _log_held(self, held):
        """Log each set of held points that changed since it was last logged."""
        for name, points in (held or {}).items():
            points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
            last = self._held.get(name)
            if last is not None and np.array_equal(last, points):
                continue        # pins hold still: latest-at shows the last ones
            self.rec.log(f'cloth/{name}', rr.Points3D(points, radii=0.01))
            self._held[name] = points

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

    def log_start(self, record, numba_threads):
        """Log what builds the simulation again (``record``) and the kernels' thread count."""
        text = json.dumps({**record, 'numba_threads': int(numba_threads)})
        self.rec.log('replay/start', rr.TextDocument(text), static=True)

    def log_step(self, state, finest, lod, report, wall_seconds, simulated_seconds,
                 held=None, commands=()):
        """
        Log the state after a tick: meshes, held points and per-step metrics.

        ``wall_seconds``: the tick's compute time; ``simulated_seconds``: the time the tick
        advanced the simulation; ``held``: name -> held points of level ``finest``;
        ``commands``: those applied before the tick's step, in order.
        """
        now = time.monotonic()
        self.rec.set_time('sim_time', duration=state.time)
        self.rec.set_time('step', sequence=self._steps)
        if commands:
            self.rec.log('replay/commands', rr.TextLog(json.dumps(commands)))
        if self._steps % self.finest_every == 0:
            self._mesh('cloth/finest', state, finest, 0xFFFFFFFF, shaded=True)
        self._mesh('cloth/lod', state, lod, 0x3C8CDC80)
        self._log_held(held)
        values = self._metrics(state, finest, report, wall_seconds, simulated_seconds, now)
        for name, _ in METRICS:
            if values[name] is not None:
                self.rec.log(f'metrics/{name}', rr.Scalars(float(values[name])))
        self._steps += 1
        if now - self._last_flush > self.flush_period:
            self.rec.flush()
            self._last_flush = now

    def _metrics(self, state, finest, report, wall_seconds, simulated_seconds, now):
        """Return the values of :data:`METRICS` for a step; None: no value this step."""
        kin, pot, ela = energy(self.model, state, finest)
        return {'step_ms': report.seconds * 1e3,
                'headroom': simulated_seconds / wall_seconds if wall_seconds > 0 else None,
                'real_time_factor': self._real_time_factor(simulated_seconds, now),
                'levels': len(report.levels),
                'max_strain': max(report.peak_strain, report.max_strain),
                'energy': kin + pot + ela}

    def _real_time_factor(self, simulated_seconds, now):
        """Return simulated seconds per wall-clock second since the last call; None at first."""
        since, self._last_call = self._last_call, now
        if since is None or now <= since:
            return None
        return simulated_seconds / (now - since)

    def close(self):
        """Flush everything and finish the file (footer): readable after any stop."""
        self.rec.flush()
        self.rec.disconnect()
