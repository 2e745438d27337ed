"""
The peer simulators on our scene (hcloth_ros.bench.peers).

The peers are optional extras
(``pip install mujoco==3.14.0 pybullet==3.2.7 newton==1.8.0 warp-lang==1.19.0``): every
test of a peer starts with ``pytest.importorskip`` so the suite passes without them.
"""

import sys

from hcloth_ros.bench import peers
import numpy as np
import pytest

N = 9
LADDER = (1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960, 1 / 1920)

# A modest time step each peer is stable at for n = 9. MuJoCo's discrete integrator is
# implicit and stays plausible even at 1/30; PyBullet integrates the springs explicitly
# and blows up at 1/480 (strain ~1e4), so 1/960. Newton's VBD is implicit but its 10
# iterations leave 50 % strain at 1/30 and 15 % at 1/60, 2.4 % at 1/240; its semi-implicit
# solver is explicit and blows up at 1/480 (strain ~3e3), so 1/960.
STABLE_DT = {'mujoco': 1 / 240, 'pybullet': 1 / 960, 'newton_vbd': 1 / 240,
             'newton_semi_implicit': 1 / 960}

# Largest structural strain over the 2 s at those steps, measured (MuJoCo 3.14.0,
# PyBullet 3.2.7): 0.012 and 0.025; Newton 1.8.0 (Warp 1.19.0, CPU): VBD 0.0241,
# semi-implicit 0.0177. The bounds leave a factor of about two.
STRAIN_BOUND = {'mujoco': 0.03, 'pybullet': 0.05, 'newton_vbd': 0.05,
                'newton_semi_implicit': 0.04}

PIN_TOLERANCE = 1e-3      # m
START = peers.HEIGHT      # m, the cloth's initial height
FALL = 0.1                # m, the centre of mass must drop at least this much
# Lowest a 1 m cloth hanging from y = 0 can take its centre of mass, with 5 cm of slack
# for stretch (the strain bounds above are at most 5 %).
FLOOR = START - peers.SIZE - 0.05

_runs = {}


def _run(name):
    """One run of the scene per peer, shared by the tests (about 0.2 s each)."""
    if name not in _runs:
        _runs[name] = peers.run(name, N, STABLE_DT[name])
    return _runs[name]


def _assert_hangs_plausibly(name):
    r = _run(name)
    times = np.array(r['times'])
    com_z = np.array(r['com_z'])

    assert r['peer'] == name and r['n'] == N and r['dt'] == STABLE_DT[name]
    assert r['finite']
    # 61 samples, 0 to 2 s every 1/30 s
    np.testing.assert_allclose(times, np.arange(61) / 30, atol=1e-9)

    # the pinned corners stay put (the engine's pin, read back in our grid order)
    final = r['positions_final']
    assert final.shape == (N * N, 3)
    start = peers.grid_points(N)[peers.pinned_indices(N)]
    assert np.linalg.norm(final[peers.pinned_indices(N)] - start, axis=1).max() < PIN_TOLERANCE
    assert r['pin_drift'] < PIN_TOLERANCE

    # it falls: undamped, the cloth swings back up towards its start (PyBullet is at
    # 1.45 m at t = 1 s, MuJoCo 1.34 m), so "falls by 1 s" means at some sample by 1 s
    assert com_z[0] == pytest.approx(START)
    assert com_z[times <= 1.0 + 1e-9].min() < START - FALL
    assert com_z.mean() < START - FALL
    # ... but no lower than a hanging 1 m cloth can reach
    assert com_z.min() > FLOOR

    # it stretches under its weight, within the measured bound
    assert 1e-3 < r['max_strain'] < STRAIN_BOUND[name]

    # timing of the stepping loop is there and sane
    assert 0 < r['wall_seconds'] == pytest.approx(r['wall_per_sim_second'] * 2.0)
    assert isinstance(r['version'], str) and r['material']


def _assert_ladder(name):
    seen = []
    r = peers.largest_plausible_step(name, N, on_run=seen.append)
    assert r['plausible']
    assert any(r['dt'] == pytest.approx(dt) for dt in LADDER)
    # tried from the largest dt down, stopping at the first plausible one
    tried = [t['dt'] for t in r['tried']]
    assert tried == sorted(tried, reverse=True) and tried[-1] == r['dt']
    assert len(seen) == len(r['tried'])
    assert all(not s['plausible'] for s in seen[:-1])
    assert r['finite'] and r['max_strain'] <= 0.2
    return r


def test_mujoco_hangs_plausibly():
    pytest.importorskip('mujoco')
    _assert_hangs_plausibly('mujoco')


def test_pybullet_hangs_plausibly():
    pytest.importorskip('pybullet')
    _assert_hangs_plausibly('pybullet')


def _assert_one_thread(name):
    """Check that the stepping loop took about as much CPU time as wall time: one thread."""
    r = _run(name)
    assert r['cpu_seconds'] < 1.2 * r['wall_seconds'] + 0.01


def test_newton_vbd_hangs_plausibly():
    pytest.importorskip('newton')
    _assert_hangs_plausibly('newton_vbd')
    _assert_one_thread('newton_vbd')


def test_newton_semi_implicit_hangs_plausibly():
    pytest.importorskip('newton')
    _assert_hangs_plausibly('newton_semi_implicit')
    _assert_one_thread('newton_semi_implicit')


def test_mujoco_largest_plausible_step():
    pytest.importorskip('mujoco')
    r = _assert_ladder('mujoco')
    assert r['dt'] == pytest.approx(1 / 30)       # implicit: the first rung already


def test_pybullet_largest_plausible_step():
    pytest.importorskip('pybullet')
    r = _assert_ladder('pybullet')
    assert r['dt'] <= 1 / 480                     # explicit springs: a small rung


def test_newton_vbd_largest_plausible_step():
    pytest.importorskip('newton')
    r = _assert_ladder('newton_vbd')
    # implicit, but 10 iterations leave 1/30 at 50 % strain (measured 0.50): the second rung
    assert r['dt'] == pytest.approx(1 / 60)
    assert r['tried'][0]['finite'] and r['tried'][0]['max_strain'] > 0.4


def test_newton_semi_implicit_largest_plausible_step():
    pytest.importorskip('newton')
    r = _assert_ladder('newton_semi_implicit')
    # explicit springs: 1/480 blows up (strain ~3e3), 1/960 holds
    assert r['dt'] == pytest.approx(1 / 960)


def test_newton_graph_replay_is_the_solvers_step():
    """
    The recorded CPU graphs step exactly as the solver's own launches.

    Ten steps of each solver, replayed from the graphs, against ten plain steps of an
    identically built scene.
    """
    newton = pytest.importorskip('newton')
    wp = pytest.importorskip('warp')
    dt = 1 / 960
    for solver in ('vbd', 'semi_implicit'):
        with wp.ScopedDevice('cpu'), peers._silenced_output():
            model, engine, _ = peers._newton_scene(newton, N, solver)
            step, positions = peers._newton_stepper(wp, model, engine, dt)
            start = positions().copy()
            for _ in range(10):
                step()
            replayed = positions().copy()
            model, engine, _ = peers._newton_scene(newton, N, solver)
            a, b = model.state(), model.state()
            for _ in range(10):
                a.clear_forces()
                engine.step(a, b, None, None, dt)
                a, b = b, a
            launched = a.particle_q.numpy()
        np.testing.assert_array_equal(start, peers.grid_points(N).astype(np.float32))
        assert np.abs(replayed - start).max() > 1e-4        # it moved
        np.testing.assert_array_equal(replayed, launched)


def test_mujoco_membrane_matches_the_springs():
    """
    Probe MuJoCo's membrane as built (E, nu, thickness of mujoco_membrane).

    Small affine strains of a free flat flex, energy from the passive forces. Along the
    grid axes it must reproduce the spring grid's uniaxial modulus and lateral contraction
    (1983 N/m, 0.417) to 1 %; its shear is the documented 700 N/m.
    """
    mujoco = pytest.importorskip('mujoco')
    young, poisson = peers.mujoco_membrane()
    xml = f"""
<mujoco><option gravity="0 0 0" integrator="discrete"/><worldbody>
  <flexcomp name="probe" type="grid" dim="2" count="5 5 1" spacing="0.25 0.25 0.25" mass="1">
    <elasticity young="{young!r}" poisson="{poisson!r}" thickness="{peers.MUJOCO_THICKNESS!r}"
                elastic2d="both"/>
    <contact selfcollide="none" contype="0" conaffinity="0"/>
  </flexcomp>
</worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    x0 = d.flexvert_xpos[:, :2].copy()

    def energy_per_area(strain):
        """Energy (J/m^2) of the 1 m^2 square under displacement x0 @ strain^T."""
        u = np.zeros((len(x0), 3))
        u[:, :2] = x0 @ np.asarray(strain).T
        d.qpos[:] = u.ravel()      # every vertex is a body with three slide joints
        mujoco.mj_forward(m, d)
        return -0.5 * float(np.sum(d.qfrc_passive * u.ravel()))   # linear: W = -f.u/2

    e = 1e-4
    c11 = 2 * energy_per_area([[e, 0], [0, 0]]) / e ** 2
    c12 = energy_per_area([[e, 0], [0, e]]) / e ** 2 - c11
    shear = energy_per_area([[0, e], [e, 0]]) / (2 * e ** 2)

    s11, s12, s_shear = peers.spring_grid_moduli()
    assert c11 - c12 ** 2 / c11 == pytest.approx(s11 - s12 ** 2 / s11, rel=0.01)
    assert c12 / c11 == pytest.approx(s12 / s11, rel=0.01)
    assert shear == pytest.approx(0.7 * s_shear, rel=0.01)


def test_unknown_peer_is_a_value_error():
    with pytest.raises(ValueError, match='unknown peer'):
        peers.run('bullet3', N, 0.01)


def test_missing_package_is_an_import_error_with_the_pip_command(monkeypatch):
    monkeypatch.setitem(sys.modules, 'mujoco', None)     # makes `import mujoco` fail
    with pytest.raises(ImportError, match=r'pip install mujoco==3\.14\.0'):
        peers.run('mujoco', N, 0.01)
    assert 'mujoco' not in peers.available()


def test_newton_peers_missing_is_an_import_error_with_the_pip_command(monkeypatch):
    monkeypatch.setitem(sys.modules, 'newton', None)
    with pytest.raises(ImportError, match=r'pip install newton==1\.8\.0 warp-lang==1\.19\.0'):
        peers.run('newton_vbd', N, 0.01)
    assert not {'newton_vbd', 'newton_semi_implicit'} & set(peers.available())


def test_scene_helpers():
    """The scene every peer builds: our geometry, masses, pins and sampling."""
    x = peers.grid_points(N)
    assert x[0] == pytest.approx([-0.5, 0.0, 1.5]) and x[N] == pytest.approx([-0.375, 0.0, 1.5])
    np.testing.assert_allclose(x[peers.pinned_indices(N)][:, :2], [[-0.5, 0.0], [0.5, 0.0]])
    m = peers.lumped_masses(N).reshape(N, N)
    assert m.sum() == pytest.approx(peers.TOTAL_MASS)
    assert m[0, 0] * 4 == pytest.approx(m[4, 4]) and m[0, 4] * 2 == pytest.approx(m[4, 4])
    assert len(peers.structural_edges(N)) == 2 * N * (N - 1)
    assert peers.sample_steps(1 / 240, 2.0, 1 / 30) == list(range(0, 481, 8))
    shuffled = np.random.default_rng(0).permutation(N * N)
    order = peers.grid_order(x[shuffled], N)
    assert np.array_equal(x[shuffled][order], x)


def test_spring_grid_and_newton_colors():
    """Our springs as the Newton peers get them, and a VBD colouring none of them violates."""
    pairs, stiffness = peers.spring_grid(N)
    x = peers.grid_points(N)
    cells = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) * (N - 1) / peers.SIZE
    # structural, then shear (both diagonals of every cell), then bending (two apart)
    counts = [2 * N * (N - 1), 2 * (N - 1) ** 2, 2 * N * (N - 2)]
    assert len(pairs) == len(stiffness) == sum(counts)
    assert len({tuple(sorted(p)) for p in pairs.tolist()}) == len(pairs)   # no duplicates
    start = 0
    for count, k, rest in zip(counts, (peers.K_STRUCT, peers.K_SHEAR, peers.K_BEND),
                              (1.0, np.sqrt(2), 2.0)):
        np.testing.assert_allclose(cells[start:start + count], rest)
        np.testing.assert_array_equal(stiffness[start:start + count], k)
        start += count
    np.testing.assert_array_equal(pairs[:counts[0]], peers.structural_edges(N))

    groups = peers.newton_colors(N)
    color = np.full(N * N, -1)
    for c, group in enumerate(groups):
        color[group] = c
    assert len(groups) == 9 and np.all(color >= 0)
    assert sum(len(g) for g in groups) == N * N
    assert np.all(color[pairs[:, 0]] != color[pairs[:, 1]])


def test_a_blow_up_ends_the_run_as_not_finite():
    """
    A blow-up to NaN ends the run as not finite.

    No peer blows up to NaN at n = 9 on the ladder (PyBullet's blow-ups stay finite and
    are caught by the strain), so drive the sampling loop with a fake engine.
    """
    x = peers.grid_points(N)
    state = {'steps': 0}

    def step():
        state['steps'] += 1

    def positions():
        return x if state['steps'] < 10 else x * np.nan

    r = peers._simulate(step, positions, N, 1 / 240, 2.0, 1 / 30)
    assert not r['finite'] and state['steps'] == 16          # stopped at the 3rd sample
    assert len(r['com_z']) == len(r['times']) == 61
    assert r['com_z'][:2] == pytest.approx([START, START]) and np.isnan(r['com_z'][2:]).all()
    assert r['max_strain'] == 0.0
