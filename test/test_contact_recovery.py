"""
Contact across levels and recovery.

A fold over a table edge, a cloth started inside a box, a step retried in smaller steps.
"""

from hcloth_ros.core import ClothBuilder, Control, make_scene, make_solver, Placement, State
from hcloth_ros.core.recovery import step_with_retries
import numpy as np
import pytest

DT = 1 / 60
TABLE = (0.0, 0.0, 0.35, 0.3, 0.3, 0.35)


def _table_strain(contact_rounds, levels=3):
    """Largest finest strain over the 4 s of config/table.yaml's drop (multigrid)."""
    scene = make_scene(ground_z=0.0, boxes=[TABLE], friction=0.5, margin=0.002)
    model = ClothBuilder(resolution=(9, 9), level_count=levels, scene=scene, air_drag=1.0,
                         placement=Placement(origin=(-0.5, -0.5, 1.0))).finalize()
    state, control = State.at_rest(model), Control(model)
    solver = make_solver('multigrid', model, contact_rounds=contact_rounds)
    worst = 0.0
    for _ in range(240):
        report = solver.step(state, control, DT)
        assert report.ok
        worst = max(worst, report.max_strain)
    return worst


def test_a_cloth_folding_over_a_table_edge_keeps_the_strain_limit():
    """
    Under 1.5 x the 10 % limit over the whole drop at 33 x 33 (0.111 measured).

    Without the rounds of strain limiting and contact on the refinement levels (coarser
    levels then taking the finest state) the refined points wrap the edge between
    inherited points already too close: 0.70 measured.
    """
    assert _table_strain(16) < 1.5 * 0.1
    assert _table_strain(0) > 0.5


def test_the_table_edge_strain_holds_at_65_by_65():
    """
    0.134 measured; 0.22 when only the finest level ran the rounds.

    Each refinement level that touches the table wraps it before the next level steps, so
    the 65 x 65 level inherits points that already lie round the edge.
    """
    assert _table_strain(16, levels=4) < 1.5 * 0.1


@pytest.mark.parametrize('solver', ['multigrid', 'hierarchical'])
def test_a_cloth_started_across_a_box_leaves_it_within_a_second(solver):
    """169 of 1089 finest points start inside; none is after 1 s (one step measured)."""
    box = np.array([0.0, 0.0, 0.5, 0.2, 0.2, 0.1])
    model = ClothBuilder(resolution=(9, 9), level_count=3,
                         scene=make_scene(ground_z=0.0, boxes=[box]),
                         placement=Placement((-0.5, -0.5, 0.5), (1, 0, 0), (0, 1, 0))).finalize()
    state, control = State.at_rest(model), Control(model)
    stepper = make_solver(solver, model)

    def inside():
        return int(np.all(np.abs(state.points(2) - box[:3]) < box[3:], axis=1).sum())
    assert inside() == 169
    for _ in range(60):
        assert stepper.step(state, control, DT).ok
    assert inside() == 0
    for k in range(3):     # every level, with the margin
        grown = np.all(np.abs(state.points(k) - box[:3]) < box[3:] + 0.002 - 1e-9, axis=1)
        assert not grown.any()


def test_refused_steps_are_retried_in_smaller_steps():
    """
    Symplectic Euler at 1/60 s on a cloth stable only below about 1/200 s.

    Stepped plainly it blows up and every step after is refused (frozen at 0.05 s); each
    refused step retried in 2, 4, then 8 steps, it runs the whole 2 s.
    """
    model = ClothBuilder(resolution=(9, 9), level_count=1, k_struct=100.0, k_shear=100.0,
                         k_bend=10.0).finalize()

    def run(retry):
        state, control = State.at_rest(model), Control(model)
        control.set_pins([0, 8])
        solver = make_solver('explicit', model, strain_limit=None)
        splits = []
        for _ in range(120):
            if retry:
                splits.append(step_with_retries(solver, state, control, DT)[1])
            else:
                solver.step(state, control, DT)
        return state, splits
    frozen, _ = run(False)
    assert frozen.time < 0.1
    state, splits = run(True)
    assert state.time == pytest.approx(2.0) and 0 not in splits and max(splits) > 1
    assert np.all(np.isfinite(state.q[0]))
