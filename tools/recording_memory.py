"""
Resident memory of the engine stepped with and without a Rerun recording.

    .venv/bin/python tools/recording_memory.py recording --steps 21000
    .venv/bin/python tools/recording_memory.py none --steps 21000

The default scene stepped ``--steps`` times with a gripper grasping, lifting and releasing
the free corner every 240 steps (as the soak's client does), its commands taken every
step; ``recording`` logs each step to a recording in a temporary folder (finest mesh every
30th step, the commands), ``commandless`` the same without the commands, ``none`` records
nothing. Prints the resident memory every 3,000 steps: what grows, the engine or the
recording, without ROS in the way.
"""

import argparse
import os
import tempfile

from hcloth_ros import params
from hcloth_ros.core.poses import pose_fields
from hcloth_ros.recorder import Recorder
from hcloth_ros.simulation import Simulation
import numpy as np


def resident_mb():
    """Return this process's resident memory (MB) from /proc."""
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 1e6


def gripper_cycle(sim, n, corner):
    """Grasp the corner at step 0 of every 240, lift it 2 mm a step, release at 120."""
    phase = n % 240
    if phase == 0:
        sim.apply(['grasp', 'g', [80], *pose_fields(np.eye(3), corner)])
    elif phase < 120:
        sim.apply(['move', 'g', np.eye(3).tolist(), (corner + [0, 0, 0.002 * phase]).tolist()])
    elif phase == 120:
        sim.apply(['release', 'g'])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('mode', choices=['recording', 'commandless', 'none'])
    parser.add_argument('--steps', type=int, default=21000)
    args = parser.parse_args(argv)
    sim = Simulation.build(params.resolve())
    with tempfile.TemporaryDirectory() as work:
        recorder = None
        if args.mode != 'none':
            recorder = Recorder(sim.model, path=os.path.join(work, 'run.rrd'), finest_every=30)
            recorder.log_start(sim.start_record(), 1)
        corner = sim.state.points_by_id(sim.model, 3)[80]
        for n in range(args.steps + 1):
            gripper_cycle(sim, n, corner)
            commands = sim.take_commands()
            report = sim.advance()
            if recorder is not None:
                recorder.log_step(sim.state, 3, 1, report, 0.002, sim.dt,
                                  commands=commands if args.mode == 'recording' else ())
            if n % 3000 == 0:
                print(f'{args.mode}: step {n}, resident {resident_mb():.1f} MB', flush=True)
        if recorder is not None:
            recorder.close()


if __name__ == '__main__':
    main()
