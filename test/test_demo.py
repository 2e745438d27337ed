"""The README's main job: the headless demo writes its pictures."""

import os

import matplotlib.image as mpimg
import numpy as np

from hcloth_ros import demo, params


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
    values = params.resolve(params.load_file(demo.config_path('hanging.yaml')))
    model, shots, curves = demo.simulate(values, 0.5, [0.0, 0.5], progress=False)
    (t0, s0), (t1, s1) = shots
    assert (t0, t1) == (0.0, 0.5)
    assert curves['com_z'][-1] < 1.5 - 0.05
    pins = model.level(3).id_to_grid[[0, 8]]
    assert np.array_equal(s0.points(3)[pins], s1.points(3)[pins])
