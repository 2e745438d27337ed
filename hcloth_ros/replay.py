"""
Re-simulate a node's recording offline and say how far it is from what was recorded.

    hcloth_replay RECORDING.rrd [--set NAME=VALUE ...] [--tolerance M]

A recording made by ``sim_node`` (``rerun_path``) holds what built its simulation
(``replay/start``) and every command the node applied, on the step it came before
(``replay/commands``; :mod:`hcloth_ros.simulation`). This builds the same simulation,
applies the commands before the same steps, and compares each recorded finest mesh
(every ``rerun_finest_every``-th step, float32 as recorded) with the replayed one. It
prints the largest difference in metres: 0 for a recording made with the same engine and
parameters, whatever the timing of the run was (which tick a message landed on is in the
commands). The engine is the package's sources that simulate and the Python, numpy and
numba versions (:func:`~hcloth_ros.simulation.engine`): a recording keeps them, and the
replay says on stderr which of them changed since (an edited kernel may move the cloth
under the same version number). ``--set`` re-simulates with a parameter changed (what
would a stiffer cloth have done under the same commands?); the difference then says how
far that moved it.

Exit status: 0 when the largest difference is at most ``--tolerance`` (default 0), 1 when
above, 2 when the recording cannot be replayed (no start record, another format).
"""

import argparse
import json
import sys
import time

from hcloth_ros import params
from hcloth_ros.simulation import engine_changes, FORMAT, Simulation, version
import numpy as np
import yaml

PROGRESS_PERIOD = 2.0   # s between progress lines


class ReplayError(Exception):
    """The recording cannot be replayed; the message says why."""


def _texts(batch, column):
    """Return the JSON texts of a text column, one per row (None where a row has none)."""
    return [row[0] if row else None for row in batch.column(column).to_pylist()]


def read_commands(path):
    """
    Return ``(start, commands)``: the start record and step -> commands, from a recording.

    Raises ReplayError when the file holds no start record or one of another format.
    """
    from rerun.chunk import RrdReader
    start, commands = None, {}
    for chunk in RrdReader(path).stream():
        if chunk.entity_path == '/replay/start':
            start = json.loads(_texts(chunk.to_record_batch(), 'TextDocument:text')[-1])
        elif chunk.entity_path == '/replay/commands':
            batch = chunk.to_record_batch()
            for step, text in zip(batch.column('step').to_pylist(),
                                  _texts(batch, 'TextLog:text')):
                commands.setdefault(step, []).extend(json.loads(text))
    if start is None:
        raise ReplayError(f'{path} has no replay/start: not a sim_node recording, or one '
                          'made before recordings held their commands')
    if start.get('format') != FORMAT:
        raise ReplayError(f'{path} is in replay format {start.get("format")}; this version '
                          f'reads format {FORMAT}')
    return start, commands


def recorded_meshes(path):
    """Yield ``(step, positions (n, 3) float32)`` of the finest meshes, in step order."""
    from rerun.chunk import RrdReader
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != '/cloth/finest':
            continue
        batch = chunk.to_record_batch()
        if 'Mesh3D:vertex_positions' not in batch.schema.names:
            continue
        column = batch.column('Mesh3D:vertex_positions')
        steps = batch.column('step').to_pylist()
        for row in np.argsort(steps, kind='stable'):
            cell = column[int(row)]
            if cell.is_valid and len(cell):
                flat = cell.values.flatten().to_numpy(zero_copy_only=False)
                yield steps[row], flat.astype(np.float32).reshape(-1, 3)


def parse_settings(pairs):
    """Return ``{name: value}`` of ``NAME=VALUE`` strings, values read as YAML (ValueError)."""
    out = {}
    for pair in pairs:
        name, sep, text = pair.partition('=')
        if not sep or name not in params.PARAM_BY_NAME:
            raise ValueError(f'--set {pair!r}: expected NAME=VALUE with NAME one of the '
                             'engine parameters (README parameter table)')
        value = yaml.safe_load(text)
        reason = params.check_value(params.PARAM_BY_NAME[name], value)
        if reason:
            raise ValueError(f'--set {reason}')
        out[name] = value
    return out


class Replay:
    """A recording's simulation, stepped on demand up to a recorded step."""

    def __init__(self, start, commands, settings=None):
        values = {**start['values'], **(settings or {})}
        self.sim = Simulation.build(values)
        self.sim.add_moving_obstacles(start['moving_obstacles'])
        self.commands = commands
        self.step = -1      # the last step simulated

    def advance_to(self, step):
        """Apply the commands and step until ``step`` has been simulated."""
        while self.step < step:
            self.step += 1
            for command in self.commands.get(self.step, ()):
                self.sim.apply(command)
            self.sim.advance()

    def finest_points(self):
        """Return the finest simulated level's positions as the recorder logs them (float32)."""
        q = self.sim.state.q[self.sim.solver.levels()[-1]]
        return q.reshape(3, -1).T.astype(np.float32)


def compare(path, settings=None, progress=True):
    """
    Replay ``path`` and compare; return a dict of the outcome.

    Keys: ``meshes`` compared, ``steps`` simulated, ``simulated`` seconds, ``largest``
    difference (m; inf where a mesh's level differs), ``at`` (step, point) of it,
    ``version`` the recording was made with, ``engine`` its
    :func:`~hcloth_ros.simulation.engine` (None in recordings made before they kept it).
    """
    start, commands = read_commands(path)
    replay = Replay(start, commands, settings)
    largest, at, meshes = 0.0, None, 0
    last_said = time.monotonic()
    for step, recorded in recorded_meshes(path):
        if step <= replay.step:
            raise ReplayError(f'{path}: finest meshes out of step order at step {step}')
        replay.advance_to(step)
        mine = replay.finest_points()
        meshes += 1
        if mine.shape != recorded.shape:
            diff, point = float('inf'), -1
        else:
            d = np.abs(mine.astype(np.float64) - recorded).max(axis=1)
            point = int(np.argmax(d))
            diff = float(d[point])
        if at is None or diff > largest:
            largest, at = diff, (step, point)
        if progress and time.monotonic() - last_said > PROGRESS_PERIOD:
            print(f'[replay] step {step}, t = {replay.sim.state.time:.2f} s, largest '
                  f'difference so far {largest:.3g} m', file=sys.stderr, flush=True)
            last_said = time.monotonic()
    return {'meshes': meshes, 'steps': replay.step + 1, 'simulated': replay.sim.state.time,
            'largest': largest, 'at': at, 'version': start.get('version'),
            'engine': start.get('engine')}


def describe(outcome):
    """Return the outcome as one line for people."""
    where = ''
    if outcome['largest'] > 0 and outcome['at'] is not None:
        step, point = outcome['at']
        where = f' (step {step}, point {point})' if point >= 0 else \
            f' (step {step}: another level was simulated there)'
    return (f'replayed {outcome["steps"]} steps: {outcome["meshes"]} finest meshes '
            f'compared, largest difference {outcome["largest"]:.6g} m{where}')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('recording', help='an .rrd file written by sim_node (rerun_path)')
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                        help='re-simulate with an engine parameter changed (repeatable)')
    parser.add_argument('--tolerance', type=float, default=0.0,
                        help='largest difference (m) that still exits 0 (default 0)')
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    try:
        settings = parse_settings(args.set)
        outcome = compare(args.recording, settings)
    except (ReplayError, ValueError, OSError) as e:
        print(f'[replay] error: {e}', file=sys.stderr)
        return 2
    if outcome['version'] != version():
        print(f'[replay] recorded with hcloth_ros {outcome["version"]}, replayed with '
              f'{version()}: differences may come from the versions', file=sys.stderr)
    changes = engine_changes(outcome['engine'])
    if changes:
        print(f'[replay] the engine changed since the recording ({"; ".join(changes)}): '
              'differences may come from that', file=sys.stderr)
    print(f'[replay] {describe(outcome)}; {time.monotonic() - t0:.1f} s')
    return 0 if outcome['largest'] <= args.tolerance else 1


if __name__ == '__main__':
    sys.exit(main())
