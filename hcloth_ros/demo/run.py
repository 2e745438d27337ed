"""
The README's main job: sim_node on the fold scene plus a scripted robot, recorded.

    hcloth_demo_run [--out out/fold.rrd]

Starts ``sim_node`` the way ``ros2 run`` does (ament index -> lib/hcloth_ros/sim_node)
with ``config/fold.yaml`` and a Rerun recording, starts the fold client in a second
process, waits for it to finish, stops the node with Ctrl-C (SIGINT) and says how to look
at the recording.
"""

import argparse
import os
import signal
import subprocess
import sys
import time

from hcloth_ros.demo.fold_metrics import describe, fold_metrics
from hcloth_ros.params import config_path
import numpy as np


def sim_node_path():
    prefix = os.environ.get('AMENT_PREFIX_PATH') or sys.prefix
    os.environ['AMENT_PREFIX_PATH'] = prefix
    from ament_index_python.packages import get_package_prefix
    return os.path.join(get_package_prefix('hcloth_ros'), 'lib', 'hcloth_ros', 'sim_node')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', default='out/fold.rrd', help='recording to write')
    parser.add_argument('--scene', default=config_path('fold.yaml'))
    args = parser.parse_args(argv)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    node_cmd = [sim_node_path(), '--ros-args', '--params-file', args.scene,
                '-p', f'rerun_path:={os.path.abspath(args.out)}',
                # a short run: every finest mesh (the fold measures read the last one)
                '-p', 'rerun_finest_every:=1']
    print('[demo] starting', ' '.join(node_cmd), flush=True)
    node = subprocess.Popen(node_cmd)
    try:
        client = subprocess.run([sys.executable, '-m', 'hcloth_ros.demo.fold_client'],
                                timeout=120)
        time.sleep(1.0)     # let the cloth settle on camera
    finally:
        node.send_signal(signal.SIGINT)
        code = node.wait(timeout=20)
    if client.returncode or code:
        print(f'[demo] failed: client exit {client.returncode}, node exit {code}')
        return 1
    from rerun.chunk import RrdReader
    steps = sum(c.num_rows for c in RrdReader(args.out).stream()
                if c.entity_path == '/metrics/step_ms')
    print(f'[demo] recorded {steps} ticks to {args.out}; view it with\n'
          f'    .venv/bin/rerun {args.out}\n'
          f'or in a browser: .venv/bin/rerun --web-viewer --bind 127.0.0.1 {args.out}')
    print(f'[demo] {describe(fold_metrics(*finest_grids(args.out)))}')
    return 0


def finest_grids(path):
    """
    Return the first and the last finest mesh of a recording as ``(rows, cols, 3)`` grids.

    The first at the last one's level: the governor may have simulated fewer levels on a
    busy machine, and a coarser level's points are every other point of the finer one
    (every level of the fold scene is a square grid).
    """
    from rerun.chunk import RrdReader
    meshes = []
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == '/cloth/finest' and \
                'Mesh3D:vertex_positions' in batch.schema.names:
            meshes += [m for m in batch.column('Mesh3D:vertex_positions').to_pylist() if m]
    first, last = (np.array(m) for m in (meshes[0], meshes[-1]))
    side, first_side = (int(round(np.sqrt(len(m)))) for m in (last, first))
    every = (first_side - 1) // (side - 1)
    return first.reshape(first_side, first_side, 3)[::every, ::every], \
        last.reshape(side, side, 3)


if __name__ == '__main__':
    sys.exit(main())
