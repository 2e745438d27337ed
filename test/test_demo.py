"""The README's main job: the headless demo writes its pictures."""

import os

from conftest import load_tool
from hcloth_ros import params
from hcloth_ros.demo import fold_client
from hcloth_ros.demo import headless as demo
import matplotlib.image as mpimg
import numpy as np
import pytest


def test_demo_writes_snapshots_and_curves(tmp_path, capsys):
    demo.main(['--seconds', '0.5', '--out', str(tmp_path)])
    for name in ('snapshots.png', 'curves.png'):
        image = mpimg.imread(os.path.join(tmp_path, name))
        # a real picture: several hundred pixels each way, not a single colour
        assert image.shape[0] > 200 and image.shape[1] > 500
        assert np.ptp(image[..., :3]) > 0.5
    out = capsys.readouterr().out
    assert 'step median' in out and 'wrote' in out


def test_demo_simulation_follows_the_scene():
    # 0.5 s of the hanging scene: the free corners fall, the pinned ones stay; the
    # centre of mass must have dropped by more than 5 cm (free fall would be 1.2 m).
    values = params.resolve(params.load_file(params.config_path('hanging.yaml')))
    model, shots, curves = demo.simulate(values, 0.5, [0.0, 0.5], progress=False)
    (t0, s0), (t1, s1) = shots
    assert (t0, t1) == (0.0, 0.5)
    assert curves['com_z'][-1] < 1.5 - 0.05
    pins = model.level(3).id_to_grid[[0, 8]]
    assert np.array_equal(s0.points(3)[pins], s1.points(3)[pins])


@pytest.mark.slow
def test_fold_demo_folds_the_cloth_and_leaves_a_recording(tmp_path, monkeypatch):
    # The README's run command: node + scripted client in separate processes over DDS.
    # After the fold the two corners that started at y = -0.5 lie near the far edge
    # (y > 0.3) on the ground, so the cloth is doubled over: its y extent has halved.
    # The fold measures (demo/fold_metrics.py) against issue 10's targets: none of the
    # top layer below the bottom one, the far edge moved at most 2 cm, the crease within
    # 2 cm of the middle, where the client folds (four runs of the demo on 2026-11-30: 0,
    # 0.0 cm and 1.7-1.8 cm; tools/fold_jitter.py, the engine with the node's command
    # timing at random: 0, 0.0 cm, 1.7-1.9 cm in 24 runs; README, "The fold demo").
    import random
    import sys

    from rerun.chunk import RrdReader

    from hcloth_ros.demo import run as demo_run
    from hcloth_ros.demo.fold_metrics import fold_metrics
    monkeypatch.setenv('ROS_DOMAIN_ID', str(random.randint(100, 200)))
    monkeypatch.setenv('AMENT_PREFIX_PATH', sys.prefix)
    out = str(tmp_path / 'fold.rrd')
    assert demo_run.main(['--out', out]) == 0
    last = None
    for chunk in RrdReader(out).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == '/cloth/finest' and \
                'Mesh3D:vertex_positions' in batch.schema.names:
            last = batch.column('Mesh3D:vertex_positions').to_pylist()[-1]
    # the scene turns the governor off (65 x 65 throughout), but any level is a square
    # grid of the same cloth: the side is read from the mesh
    points = np.array(last)
    side = int(round(np.sqrt(len(points))))
    grid = points.reshape(side, side, 3)
    assert grid[0, 0, 1] > 0.3 and grid[0, -1, 1] > 0.3
    assert grid[0, 0, 2] < 0.05 and grid[0, -1, 2] < 0.05
    assert np.ptp(grid[..., 1]) < 0.7
    metrics = fold_metrics(*demo_run.finest_grids(out))
    assert metrics['top_below'] == 0
    assert metrics['far_edge_moved'] <= 0.02 and metrics['fold_offset'] <= 0.02


def test_fold_measures_on_a_folded_grid_built_by_hand():
    """A 33 x 33 cloth folded exactly 4 mm above its far half, then its top sunk 1 cm."""
    from hcloth_ros.demo.fold_metrics import fold_metrics
    u, v = np.meshgrid(np.linspace(-0.5, 0.5, 33), np.linspace(-0.5, 0.5, 33))
    before = np.stack([u, v, np.full_like(u, 0.002)], axis=-1)
    after = before.copy()
    after[:16, :, 1] = -before[:16, :, 1]          # the near half mirrored onto the far one
    after[:16, :, 2] = 0.006
    metrics = fold_metrics(before, after)
    assert metrics['top_below'] == 0 and metrics['far_edge_moved'] == 0.0
    assert metrics['fold_line'] == pytest.approx(0.0) and metrics['fold_offset'] < 1e-12
    # a flattened crease: a top-layer point on the ground in the bottom layer's
    # footprint, 4 nm under it (129 x 129 folds), is level; 2 um under is through
    after[15, 10, 1], after[15, 10, 2] = 0.49, 0.002 - 4e-9
    assert fold_metrics(before, after)['top_below'] == 0
    after[15, 10, 2] = 0.002 - 2e-6
    assert fold_metrics(before, after)['top_below'] == 1
    after[:16, :, 2] = -0.004                      # sunk through the bottom layer
    after[-1, :, 1] += 0.03                         # and the far edge dragged 3 cm
    sunk = fold_metrics(before, after)
    assert sunk['top_below'] == 16 * 33 and sunk['far_edge_moved'] == pytest.approx(0.03)


def test_the_fold_in_the_engine_with_the_node_timing_meets_the_fold_targets():
    """
    The demo's fold without ROS: tools/fold_jitter.py, its timing drawn from seed 17.

    Seed 17 left a top-layer point below the bottom layer when the grippers did not turn
    with the corners (``--translate-only --lift 0.25 --stop-short 0.01``, the path before;
    the demo failed a CI run on it); the same targets as the demo's.
    """
    costs = []
    metrics = _fold_in_the_engine(17, costs=costs)
    assert metrics['top_below'] == 0
    assert metrics['far_edge_moved'] <= 0.02 and metrics['fold_offset'] <= 0.02
    # ``--contact-cost``'s figures: a tick after the first each, self-contact part of the
    # tick; no pair while the corners rise (the layers apart), pairs in most ticks once
    # the top layer lies on the bottom one (297-305 of 479 ticks, seeds 0 and 1)
    kernel, pairs, tick = (np.array(c, dtype=float) for c in zip(*costs))
    assert len(costs) == int(round((fold_client.DURATION + 4.0) * 60)) - 1
    assert np.all(kernel > 0.0) and np.all(kernel < tick)
    assert not pairs[:100].any() and np.count_nonzero(pairs) > 200
    summary = load_tool('fold_jitter').cost_summary(costs)
    assert f'{np.count_nonzero(pairs)} ticks whose first check found pairs' in summary


def test_the_multigrid_solver_folds_the_cloth_without_tearing_it():
    """
    The same fold under ``multigrid`` (BDF2 on the 33 x 33 level, eq. 7 on 65 x 65).

    With three Newton iterations whatever the residual, the solves left springs at 30-50 %
    once the layers met and the cloth tore: 1795 top-layer points below the bottom layer,
    far edge 42.6 cm, largest strain 3.2 on 65 x 65 solved; with level 0 solved, far edge
    15.3 cm and the cloth unfolded (issue 10's note). Iterating while the residual is above
    tolerance, 8 seeds of tools/fold_jitter.py gave 0 below, far edge 0.2-0.3 cm and the
    crease 1.5-5.3 cm from the middle: the demo's targets but the crease's, where the
    bending springs, no longer damped away, hold a loop.
    """
    metrics = _fold_in_the_engine(17, {'solver.name': 'multigrid', 'solver.accurate_level': 0})
    assert metrics['top_below'] == 0
    assert metrics['far_edge_moved'] <= 0.02 and metrics['fold_offset'] <= 0.06


def test_the_multigrid_solver_solving_the_finest_level_holds_the_fold():
    """
    The fold with ``multigrid`` solving its 65 x 65 finest level (seed 0), the demo's targets.

    With the corrections made after the solve kept in BDF2's history (before 2026-11-30,
    session 36) the cloth gained kinetic energy lying on itself after the release (0.09 to
    52 mJ in a second) and its fold rolled open: the crease ended 50.5 cm from the middle.
    Left out of it (``MultigridSolver._corrections_leave_history``), the crease ends 1.5
    cm from it.
    """
    metrics = _fold_in_the_engine(0, {'solver.name': 'multigrid',
                                      'solver.solved_strain_limit': 0.1})
    assert metrics['top_below'] == 0
    assert metrics['far_edge_moved'] <= 0.02 and metrics['fold_offset'] <= 0.02


@pytest.mark.parametrize('shed, restore', [(180, 270), (240, 330)])
def test_a_level_shed_while_the_layers_meet_comes_back_without_crossing_them(shed, restore):
    """
    The governor's case: 65 x 65 dropped at tick ``shed``, the fold goes on on 33 x 33.

    Brought back at tick ``restore`` (180 -> 270: while the grippers still carry the top
    layer; 240 -> 330: after they let go), the level starts from the prolonged 33 x 33
    fold and is pushed out of itself (``SelfContact.settle``); at the end no top-layer
    point is below the bottom layer and the demo's targets hold. Before ``settle`` the
    33 x 33 crease, tighter than that level's ring, came back with 5-8 top-layer points
    lying level with the bottom layer's first cell at the crease's ends by the side
    edges, pushed under it by the first step, for good (seeds 14-19; this test ran the
    client's earlier, looser path then). With it, ``tools/fold_jitter.py --shed 180
    --restore 270`` (seeds 14-25) and ``--shed 240 --restore 330`` (seeds 14-19): 0
    below, far edge 0.0-0.1 cm, crease 1.6-1.9 cm from the middle.
    """
    metrics = _fold_in_the_engine(17, shed=shed, restore=restore)
    assert metrics['side'] == 65
    assert metrics['top_below'] == 0
    assert metrics['far_edge_moved'] <= 0.02 and metrics['fold_offset'] <= 0.02


def _fold_in_the_engine(seed, overrides=None, shed=None, restore=None, costs=None):
    """
    Fold measures of tools/fold_jitter.py's run of ``seed``.

    ``overrides``: parameter values; ``shed``, ``restore``: the ticks the finest level is
    dropped and brought back; ``costs``: a list for the run's self-contact times.
    """
    from hcloth_ros.demo.fold_metrics import fold_metrics
    jitter = load_tool('fold_jitter')
    before, after = jitter.run(seed, overrides=overrides, shed=shed, restore=restore,
                               costs=costs)
    side = int(round(np.sqrt(len(before))))
    metrics = fold_metrics(before.reshape(side, side, 3), after.reshape(side, side, 3))
    metrics['side'] = side      # the grid measured: the finest level simulated at the end
    return metrics
