"""The evidence benchmark's building blocks, and a smoke run of the whole command."""

import csv
import json

from hcloth_ros.bench import errors
from hcloth_ros.bench.__main__ import main as bench_main
from hcloth_ros.bench.reference import convergence_order, reference, reference_dt
from hcloth_ros.bench.scenarios import (closed_form_free_fall, level0_side, Run,
                                        SAMPLE_EVERY, simulate)
from hcloth_ros.bench.stability import explicit_boundary_check
import numpy as np
import pytest

G = 9.81


def _run(points, energy=None, com=None, failed='', max_strain=0.0):
    points = np.asarray(points, float)
    times = np.arange(len(points)) * SAMPLE_EVERY
    return Run('swing', 'test', {}, 2, 1, SAMPLE_EVERY, times[-1], times=times, points=points,
               com=points.mean(axis=1) if com is None else com,
               energy=np.zeros(len(points)) if energy is None else np.asarray(energy, float),
               max_strain=max_strain, failed=failed)


def test_error_metrics_on_known_offsets():
    rng = np.random.default_rng(1)
    ref = _run(rng.normal(size=(5, 4, 3)), energy=[3.0] * 5)
    shifted = _run(ref.points + [0.0, 0.3, 0.4], energy=[3.0, 2.8, 2.6, 2.4, 2.2])
    # every vertex 0.5 m away at every sample
    assert errors.position_rms(shifted, ref) == pytest.approx(0.5)
    assert errors.com_rms(shifted, ref) == pytest.approx(0.5)
    # 0.8 J lost in 4 samples of 1/30 s while the reference kept its energy
    assert errors.excess_energy_loss_rate(shifted, ref) == pytest.approx(0.8 / (4 / 30))
    # a run that stopped early is judged over the samples it has
    short = _run(ref.points[:2] + [0.0, 0.0, 1.0])
    assert errors.position_rms(short, ref) == pytest.approx(1.0)
    # the first second: samples at t <= 1 s only (31 of 40 at 1/30 s)
    ref = _run(np.zeros((40, 4, 3)))
    late = _run(np.where(ref.times[:, None, None] <= 1.0 + 1e-9, 0.2, 3.0) * [1.0, 0.0, 0.0])
    assert errors.first_second_rms(late, ref) == pytest.approx(0.2)


def test_stability_classifier():
    pts = np.zeros((3, 4, 3))
    assert errors.classify(_run(pts, max_strain=0.1)) == errors.STABLE
    assert errors.classify(_run(pts, max_strain=0.3)) == errors.OVERSTRETCHED
    assert errors.classify(_run(pts, failed='refused')) == errors.BLOWN_UP
    nan = pts.copy()
    nan[2, 1, 0] = np.nan
    assert errors.classify(_run(nan)) == errors.BLOWN_UP
    # energy running away beyond 100 m g L (196 J) blows up; 10 J of strain does not
    assert errors.classify(_run(pts, energy=[0.0, 50.0, 250.0])) == errors.BLOWN_UP
    assert errors.classify(_run(pts, energy=[0.0, 10.0, 10.0])) == errors.STABLE


def test_pareto_front_keeps_only_unbeaten_runs():
    cost = [1.0, 2.0, 3.0, 0.5, 2.5]
    err = [0.5, 0.2, 0.3, 0.9, 0.1]
    assert errors.pareto_front(cost, err) == [3, 0, 1, 4]
    assert errors.pareto_front([1.0, 2.0], [np.nan, 0.3]) == [1]


def test_explicit_free_fall_error_is_the_first_order_term():
    # symplectic Euler from rest: z_n = z_0 - g h^2 n (n + 1) / 2, so against the closed
    # form every point is g h t / 2 too low (t = n h); the RMS over samples follows
    dt, duration = 1 / 240, 0.4
    run = simulate('free_fall', 'explicit', 5, 1, dt, duration, options={'strain_limit': None})
    exact = closed_form_free_fall(5, duration)
    expected = np.sqrt(np.mean((G * dt * exact.times / 2) ** 2))
    assert errors.position_rms(run, exact) == pytest.approx(expected, rel=1e-6)
    # and its energy: kinetic m (g h n)^2 / 2 against a potential drop of
    # m g^2 h^2 n (n + 1) / 2 loses m g^2 h t / 2, a steady m g^2 h / 2 watts
    assert errors.excess_energy_loss_rate(run, exact) == pytest.approx(0.2 * G ** 2 * dt / 2,
                                                                       rel=1e-6)


def test_reference_converges_at_first_order_and_checks_itself():
    order, d1, d2 = convergence_order('swing', 5, 0.3, 1 / 960)
    assert 0.8 < order < 1.3 and d2 < d1
    ref, check = reference('swing', 5, 0.3)
    assert ref.dt == reference_dt(5) / 2 and not ref.failed
    # halving the step moves the vertices by about d(dt_ref): far below what it judges
    assert 0 < check < 2e-3


def test_explicit_boundary_check_brackets_the_theory():
    rows = [{'method': 'explicit', 'k': 1e3, 'dt': dt, 'status': s} for dt, s in
            ((1e-3, errors.STABLE), (2e-3, errors.STABLE), (4e-3, errors.BLOWN_UP))]
    assert explicit_boundary_check(rows, {1e3: 3e-3})[0]['consistent'] is True
    assert explicit_boundary_check(rows, {1e3: 1.5e-3})[0]['consistent'] is False
    assert explicit_boundary_check(rows[:2], {1e3: 3e-3})[0]['consistent'] is None


def test_level_split_of_the_finest_mesh():
    assert [level0_side(33, lv) for lv in (1, 2, 3, 4)] == [33, 17, 9, 5]
    with pytest.raises(ValueError, match='cannot be split'):
        level0_side(33, 7)


@pytest.mark.slow
def test_tiny_benchmark_writes_well_formed_outputs(tmp_path):
    bench_main(['--tiny', '--out', str(tmp_path), '--no-progress'])
    for name in ('accuracy', 'stability', 'fig3_5', 'fig6'):
        png = (tmp_path / f'{name}.png').read_bytes()
        assert png[:8] == b'\x89PNG\r\n\x1a\n' and len(png) > 10_000
    results = json.loads((tmp_path / 'results.json').read_text())
    assert results['plan']['name'] == 'tiny'
    summary = (tmp_path / 'summary.md').read_text()
    for title in ('Accuracy at dt', 'Rest shape', 'Explicit step limit', 'Violent grasps', 'Peers',
                  "The paper's figures"):
        assert f'## {title}' in summary
    rows = list(csv.DictReader(open(tmp_path / 'accuracy.csv')))
    assert len(rows) == len(results['accuracy']) > 20
    # every approximate method ran and was judged on the free fall; exact gravity falls
    # within first-order error of the closed form, the literal reading far slower
    ff = {r['method']: r for r in results['accuracy']
          if r['scenario'] == 'free_fall' and r['dt'] == pytest.approx(1 / 60)}
    assert ff['approx exact']['position_rms'] < 0.05 < ff['approx literal']['position_rms']
    assert {r['status'] for r in results['stability']} <= {
        errors.STABLE, errors.OVERSTRETCHED, errors.BLOWN_UP}
    # six older methods and the multigrid default (5 x 5 on 2 levels: no 'solved finest')
    assert len(results['violent']) == 3 * 7
    # the hung 9 x 9 cloth's rest shape: the multigrid and converged implicit solvers sit at
    # the energy minimum (within the L-BFGS stop, 1e-9 of the weight, and 4 s of settling
    # under air drag); the paper's method hangs 10 % lower, held only by strain limiting
    rest = {r['method']: r for r in results['equilibrium']}
    assert abs(rest['multigrid L1 (default)']['drop_error']) < 1e-3
    assert abs(rest['implicit tol 1e-3 m']['drop_error']) < 1e-3
    assert rest['hierarchical exact L1, 10 % strain limit']['drop_error'] > 0.05
    assert set(results['fig6']) == {'(1, 1)', '(0.5, 1)'}
    assert any(r['simulator'].startswith('hcloth') for r in results['peers'])


def test_the_targets_options_reach_both_multigrid_rows_only():
    from hcloth_ros.bench.targets import methods, METHODS
    assert methods() == list(METHODS)
    got = {label: options for label, _, options in
           methods({'newton_tolerance_steps': 'moved'})}
    assert got['multigrid'] == {'newton_tolerance_steps': 'moved'}
    assert got['multigrid full'] == {'accurate_level': None, 'newton_tolerance_steps': 'moved'}
    assert got['hierarchical'] == {}
