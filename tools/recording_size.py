"""
Where the bytes of a Rerun recording go: the node's default scene recorded for a while.

Builds the scene the node builds (``config/hanging.yaml`` with the given overrides),
simulates every level (no governor) and calls :class:`~hcloth_ros.recorder.Recorder` as
the node's tick does: the finest level, ``min(lod_level, finest)``, the held points, the
step's report, the tick's compute time (here its steps; the node's adds packing and
publishing) and the simulated time it advanced. Ticks are paced as the node's timer paces
them at its default ``real_time_factor`` unless ``--no-pace`` (the recorder's batching and
its real-time factor depend on the pace). Records ``--seconds`` simulated seconds to an
``.rrd`` in a temporary directory, showing progress on stderr, then prints the file's MB
(10^6 bytes) per simulated second, the size a 10-minute run would reach at that rate (the
parts logged once count as if they recurred: a longer run projects closer), and per
entity and component the bytes read back, raw and LZ4-compressed (the file's codec: an
estimate of each part's share). The issue's figures, at the node's defaults:

    .venv/bin/python tools/recording_size.py --seconds 60
    .venv/bin/python tools/recording_size.py --seconds 60 -p cloth.levels=5
    .venv/bin/python tools/recording_size.py --seconds 60 -o finest_every=30

``--file PATH`` reports a recording that exists instead (a node's, the demo's), over the
simulated time of its steps (the ``step`` timeline's count times the step's length, from
its ``replay/start``: resets do not shorten it):

    .venv/bin/python tools/recording_size.py --file out/fold.rrd
"""

import argparse
import collections
import os
import shutil
import sys
import tempfile
import time

import numba

TEN_MINUTES = 600.0


def _node_default(name):
    """Return a node parameter's default: the tool records what the node would."""
    from hcloth_ros.node_params import NODE_PARAMS
    return next(spec.default for spec in NODE_PARAMS if spec.name == name)


def _held_points(control, state, k):
    """Pinned and grasped points of level k, as the node's ``_held_points`` gives them."""
    from hcloth_ros.core.control import PINNED
    kind = control.holds(k).kind.ravel()
    pts = state.points(k)
    return {'pins': pts[kind == PINNED], 'grasps': pts[kind > PINNED]}


def record(path, seconds, overrides, options, lod_level, pace=1.0, out=sys.stderr):
    """
    Record ``seconds`` simulated seconds of the scene to ``path``; return the ticks.

    Mirrors the node's tick: the step is timed from the tick's start to the recorder call,
    which gets the finest simulated level, ``min(lod_level, finest)`` and the held points.
    """
    from hcloth_ros import params
    from hcloth_ros.core import warm_up
    from hcloth_ros.core.recovery import step_with_retries
    from hcloth_ros.recorder import Recorder
    values = params.resolve({**params.load_file(params.config_path('hanging.yaml')),
                             **overrides})
    warm_up(solvers=[values['solver.name']], parallel=numba.get_num_threads() > 1,
            energy=True)
    model, solver, state, control = params.build_all(values)
    finest = model.level_count - 1
    solver.set_finest_level(finest, state, control)
    lod = min(lod_level, finest)
    dt = float(values['solver.dt'])
    substeps = int(values['solver.substeps'])
    recorder = Recorder(model, path=path, **options)
    recorder.log_obstacles(model.scene, state.time)
    recorder.log_bodies(control.bodies, state.time)
    ticks = int(round(seconds / (dt * substeps)))
    period = dt * substeps / pace if pace > 0 else 0.0
    start = time.monotonic()
    shown = start
    for tick in range(ticks):
        if period:
            time.sleep(max(0.0, start + tick * period - time.monotonic()))
        t0 = time.perf_counter()
        for _ in range(substeps):
            report, _ = step_with_retries(solver, state, control, dt)
        recorder.log_step(state, finest, lod, report, time.perf_counter() - t0, dt * substeps,
                          _held_points(control, state, finest))
        if time.monotonic() - shown > 2.0 or tick == ticks - 1:
            shown = time.monotonic()
            print(f'\r{state.time:6.1f} / {seconds:g} simulated s, '
                  f'{os.path.getsize(path) / 1e6:7.1f} MB so far', end='', file=out, flush=True)
    print(file=out)
    recorder.close()
    return ticks


def _part(entity, column):
    """
    Return the report line a column counts to: (entity, component).

    The metrics' and the scene's entities are summed (each is small), and so are a row's
    id and times.
    """
    for prefix in ('/metrics/', '/scene/'):
        if entity.startswith(prefix):
            entity = prefix + '*'
    if ':' not in column:
        column = 'row ids and times'
    return entity, column


def component_bytes(path):
    """
    Map (entity, component) -> bytes in the file: ``(raw, lz4, chunks)`` Counters.

    ``raw``: the Arrow buffers of its columns; ``lz4``: the same compressed chunk by chunk
    with LZ4, the file's codec (which compresses whole messages: an estimate of the part's
    share); ``chunks``: how many chunks hold it (each repeats its schema in the file).
    """
    import pyarrow as pa
    from rerun.chunk import RrdReader
    codec = pa.Codec('lz4_frame')
    raw, lz4, chunks = collections.Counter(), collections.Counter(), collections.Counter()
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        keys = set()
        for name, column in zip(batch.schema.names, batch.columns):
            key = _part(chunk.entity_path, name)
            buffers = [b for b in column.buffers() if b is not None and b.size]
            raw[key] += sum(b.size for b in buffers)
            lz4[key] += sum(codec.compress(b).size for b in buffers)
            keys.add(key)
        chunks.update(keys)
    return raw, lz4, chunks


def _report(path, seconds, ticks, out=sys.stdout):
    """Print the file's size per simulated second and where its bytes go."""
    size = os.path.getsize(path)
    per_second = size / seconds / 1e6
    print(f'{ticks} ticks, {seconds:g} simulated s: file {size / 1e6:.2f} MB, '
          f'{per_second:.3f} MB per simulated s, {per_second * TEN_MINUTES:.0f} MB in '
          f'10 minutes', file=out)
    raw, lz4, chunks = component_bytes(path)
    total = sum(lz4.values())
    print(f'columns read back: {sum(raw.values()) / 1e6:.2f} MB raw, {total / 1e6:.2f} MB '
          'LZ4 (estimate); MB per simulated s, largest first:', file=out)
    print('       LZ4  share       raw  chunks  entity  component', file=out)
    for (entity, name), n in lz4.most_common():
        if n / seconds >= 50:      # bytes per simulated s: below, a line says nothing
            print(f'  {n / seconds / 1e6:8.4f} {100 * n / total:5.1f} % '
                  f'{raw[(entity, name)] / seconds / 1e6:8.4f} {chunks[(entity, name)]:7d}  '
                  f'{entity}  {name}', file=out)
    print(f'  the file beyond the columns (chunk schemas, framing, blueprint, footer): '
          f'{(size - total) / seconds / 1e6:.4f} MB/s', file=out)


def simulated_seconds(path):
    """Return a node's recording's simulated seconds: its steps times the tick's length."""
    from hcloth_ros.replay import read_commands
    from rerun.chunk import RrdReader
    start, _ = read_commands(path)
    steps = 0
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == '/metrics/step_ms':
            steps = max([steps] + [s + 1 for s in chunk.to_record_batch().column('step')
                                   .to_pylist()])
    values = start['values']
    return steps * values['solver.dt'] * values['solver.substeps'], steps


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seconds', type=float, default=10.0, help='simulated seconds')
    parser.add_argument('-p', '--param', action='append', default=[], metavar='NAME=VALUE',
                        help='a scene parameter override (YAML value), repeatable')
    parser.add_argument('-o', '--option', action='append', default=[], metavar='NAME=VALUE',
                        help='a Recorder keyword (YAML value), e.g. finest_every=1; default '
                        'finest_every: the node parameter rerun_finest_every')
    parser.add_argument('--lod-level', type=int, default=None,
                        help="the node's lod_level (default: its default)")
    parser.add_argument('--no-pace', action='store_true',
                        help="step as fast as possible instead of at the node's pace")
    parser.add_argument('--threads', type=int, default=1, help='numba threads')
    parser.add_argument('--keep', default='', help='also copy the .rrd to this path')
    parser.add_argument('--file', default='', help='report this recording instead')
    args = parser.parse_args(argv)
    if args.file:
        seconds, ticks = simulated_seconds(args.file)
        _report(args.file, seconds, ticks)
        return
    numba.set_num_threads(args.threads)
    from hcloth_ros import params
    options = {'finest_every': _node_default('rerun_finest_every'),
               **params.assignments(args.option)}
    lod_level = _node_default('lod_level') if args.lod_level is None else args.lod_level
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'run.rrd')
        pace = 0.0 if args.no_pace else _node_default('real_time_factor')
        ticks = record(path, args.seconds, params.overrides(args.param), options,
                       lod_level, pace)
        if args.keep:
            shutil.copyfile(path, args.keep)
        print(f'Recorder options {options}, lod_level {lod_level}')
        _report(path, args.seconds, ticks)


if __name__ == '__main__':
    main()
