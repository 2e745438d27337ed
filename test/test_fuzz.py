"""
The engine over its documented parameter ranges, property-based (hypothesis).

Whatever the solver, stiffness (over nine decades), step, resolution, levels,
contraction, obstacles and grasps within the ranges the parameter table documents, every
step either goes through with a finite state or is refused, and then, retried in smaller
steps as the node does (``core.recovery.step_with_retries``), goes through or leaves the
state exactly where it was; pinned points never move a bit. Small cloths and few steps:
the properties are about what a step may do, not about accuracy (other tests measure that).
"""

from hcloth_ros import params
from hcloth_ros.core.recovery import step_with_retries
from hypothesis import event, given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

pytestmark = pytest.mark.slow

SOLVERS = ('multigrid', 'hierarchical', 'implicit', 'explicit', 'approx')


def _decades(low, high):
    """Draw values spread evenly over the decades between low and high."""
    return st.floats(np.log10(low), np.log10(high)).map(lambda e: float(10 ** e))


@st.composite
def scenes(draw):
    """Draw resolved parameter values of a small scene anywhere in the documented ranges."""
    rows, cols = draw(st.integers(2, 6)), draw(st.integers(2, 6))
    levels = draw(st.integers(1, 3))
    values = {
        'cloth.resolution': [rows, cols], 'cloth.levels': levels,
        'cloth.width': draw(_decades(0.05, 5.0)), 'cloth.height': draw(_decades(0.05, 5.0)),
        'cloth.mass': draw(_decades(1e-3, 10.0)),
        'cloth.k_struct': draw(_decades(1e-1, 1e8)),
        'cloth.k_shear': draw(st.one_of(st.just(0.0), _decades(1e-1, 1e8))),
        'cloth.k_bend': draw(st.one_of(st.just(0.0), _decades(1e-1, 1e7))),
        'cloth.contraction': [draw(st.floats(0.0, 1.0)) for _ in range(levels)],
        'cloth.air_drag': draw(st.one_of(st.just(0.0), _decades(1e-2, 1e3))),
        'cloth.spring_damping': draw(st.one_of(st.just(0.0), _decades(1e-3, 1e2))),
        'solver.name': draw(st.sampled_from(SOLVERS)),
        'solver.accurate_level': draw(st.integers(0, 3)),
        'solver.integrator': draw(st.sampled_from(['bdf2', 'backward_euler'])),
        'solver.strain_limit': draw(st.sampled_from([0.0, 0.05, 0.1, 1.0])),
        'solver.retry_strain': draw(st.sampled_from([0.0, 0.3, 0.5])),
        'scene.ground': draw(st.booleans()),
        'scene.ground_z': draw(st.floats(-1.0, 2.0)),
        'scene.friction': draw(st.floats(0.0, 2.0)),
        'pinned_points': [-1],
    }
    if draw(st.booleans()):     # a box and a sphere somewhere near the cloth, maybe in it
        centre = [draw(st.floats(-1.0, 1.0)) for _ in range(3)]
        values['scene.boxes'] = centre + [draw(_decades(0.01, 1.0)) for _ in range(3)]
        values['scene.spheres'] = [draw(st.floats(-1.0, 1.0)) for _ in range(3)] + \
            [draw(_decades(0.01, 1.0))]
    if draw(st.booleans()):
        values['self_contact.thickness'] = draw(_decades(1e-4, 0.02))
    return params.resolve(values)


def _finite(state):
    return all(np.all(np.isfinite(a)) for a in state.q + state.qd)


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(values=scenes(), dt=_decades(1e-4, 0.1), data=st.data())
def test_every_step_is_finite_or_refused_and_pins_hold_bit_exactly(values, dt, data):
    model, solver, state, control = params.build_all(values)
    finest = model.level_count - 1
    count = model.level(finest).rows * model.level(finest).cols
    pins = data.draw(st.lists(st.integers(0, count - 1), max_size=3, unique=True))
    control.set_pins(pins)
    pinned = {k: state.q[k].reshape(3, -1)[:, model.level(k).id_to_grid[
        [i for i in pins if i < model.level(k).rows * model.level(k).cols]]].copy()
        for k in range(model.level_count)}
    if data.draw(st.booleans()):
        free = [i for i in range(count) if i not in pins]
        if free:
            control.grasp('g', free[:1], state)
    for step in range(3):
        if control.grasp_names:
            lift = data.draw(st.floats(-0.05, 0.05))
            control.move_grasp('g', np.eye(3), (0.0, 0.0, lift * (step + 1)))
        before = state.copy()
        report, steps = step_with_retries(solver, state, control, dt)
        assert _finite(state), (report.reason, values, dt)
        event(f'{values["solver.name"]}: {"refused" if steps == 0 else f"{steps} step(s)"}')
        if steps == 0:      # every try refused: the state is the one before, bit for bit
            assert not report.ok
            pairs = zip(state.q + state.qd, before.q + before.qd)
            assert all(np.array_equal(a, b) for a, b in pairs)
        else:
            assert report.ok
        for k in solver.levels():
            ids = model.level(k).id_to_grid[[i for i in pins
                                             if i < model.level(k).rows * model.level(k).cols]]
            assert np.array_equal(state.q[k].reshape(3, -1)[:, ids], pinned[k])
