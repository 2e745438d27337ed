"""
A thin Rerun logger: the cloth and its metrics on a ``sim_time`` timeline.

Entities: ``cloth/finest`` (mesh of the finest simulated level, every
``finest_every``-th step), ``cloth/lod`` (mesh of the LOD level, every step),
``cloth/pins`` and ``cloth/grasps`` (held points of the finest level), and
``metrics/*`` scalars: ``step_ms``, ``real_time_factor``, ``levels``, ``max_strain``,
``energy``. The file is flushed every ``flush_period`` seconds so a crash loses at most
that much, and :meth:`close` flushes and finishes it (footer included).
"""

import time

from hcloth_ros.core.metrics import energy
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
    held = ['+ /cloth/pins', '+ /cloth/grasps']
    meshes = rrb.Vertical(
        rrb.Spatial3DView(origin='/', name='finest level',
                          contents=['+ /cloth/finest'] + held),
        rrb.Spatial3DView(origin='/', name='LOD marker level', contents=['+ /cloth/lod'] + held))
    plots = rrb.Vertical(*(rrb.TimeSeriesView(origin=f'/metrics/{name}', name=title)
                           for name, title in METRICS))
    return rrb.Blueprint(rrb.Horizontal(meshes, plots, column_shares=[3, 2]),
                         rrb.TimePanel(timeline='sim_time'), collapse_panels=True)


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

    def _mesh(self, entity, state, k, colour):
        if self._topology.get(entity) != k:
            # topology changes with the level: logged on the timeline, not static
            self.rec.log(entity, rr.Mesh3D.from_fields(
                triangle_indices=self.model.grid_triangles(k).astype(np.uint32),
                albedo_factor=colour))
            self._topology[entity] = k
        self.rec.log(entity, rr.Mesh3D.from_fields(
            vertex_positions=state.q[k].reshape(3, -1).T.astype(np.float32)))

    def log_step(self, state, finest, lod, report, wall_seconds, simulated_seconds,
                 held=None):
        """Log the state after a tick: meshes, held points and per-step metrics."""
        self.rec.set_time('sim_time', duration=state.time)
        self.rec.set_time('step', sequence=self._steps)
        if self._steps % self.finest_every == 0:
            self._mesh('cloth/finest', state, finest, 0xF08C28FF)
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
