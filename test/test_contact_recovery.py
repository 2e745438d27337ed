"""
Contact across levels and recovery.

A fold over a table edge, a cloth started inside a box, a step retried in smaller steps.
"""

from conftest import load_tool
from hcloth_ros import params
from hcloth_ros.core import ClothBuilder, Control, make_scene, make_solver, Placement, State
from hcloth_ros.core.kernels import contact_strain
from hcloth_ros.core.recovery import retried, retry_warning, step_with_retries
from hcloth_ros.core.solvers import StepReport
from hcloth_ros.simulation import Simulation
import numpy as np
import pytest

DT = 1 / 60
TABLE = (0.0, 0.0, 0.35, 0.3, 0.3, 0.35)


def _table_strain(contact_rounds, levels=3, rising=None, **options):
    """
    Largest finest strain over the 4 s of config/table.yaml's drop (multigrid).

    ``rising``: the table is a moving box body (friction 0.5) rising at this speed (m/s)
    instead of part of the static scene, only the ground static.
    """
    boxes = [TABLE] if rising is None else []
    scene = make_scene(ground_z=0.0, boxes=boxes, friction=0.5, margin=0.002)
    model = ClothBuilder(resolution=(9, 9), level_count=levels, scene=scene, air_drag=1.0,
                         placement=Placement(origin=(-0.5, -0.5, 1.0))).finalize()
    state, control = State.at_rest(model), Control(model)

    def place(step):
        if rising is not None:
            control.bodies.set_pose('table', np.eye(3),
                                    TABLE[:2] + (TABLE[2] + rising * step * DT,))
    if rising is not None:
        control.bodies.add('table', 'box', TABLE[3:], friction=0.5)
        place(0)
        control.bodies.commit()
    solver = make_solver('multigrid', model, contact_rounds=contact_rounds, **options)
    worst = 0.0
    for step in range(240):
        place(step + 1)
        report = solver.step(state, control, DT)
        assert report.ok, report.reason
        worst = max(worst, report.max_strain)
    return worst


def test_a_cloth_folding_over_a_table_edge_keeps_the_strain_limit():
    """
    Under 1.5 x the 10 % limit over the whole drop at 33 x 33.

    0.106 measured (0.111 with the rounds' Jacobi strain limiting).

    Without the rounds of strain limiting and contact on the refinement levels (coarser
    levels then taking the finest state) the refined points wrap the edge between
    inherited points already too close: 0.70 measured.
    """
    assert _table_strain(16) < 1.5 * 0.1
    assert _table_strain(0) > 0.5


def test_the_table_edge_strain_holds_at_65_by_65():
    """
    Under 1.5 x the 10 % limit at 65 x 65 too.

    0.106 measured (0.131 with the rounds' Jacobi strain limiting); 0.22 when only the
    finest level ran the rounds (Jacobi).

    Each refinement level that touches the table wraps it before the next level steps, so
    the 65 x 65 level inherits points that already lie round the edge.
    """
    assert _table_strain(16, levels=4) < 1.5 * 0.1


def test_strain_limiting_along_the_table_holds_the_edge_at_129_by_129():
    """
    Under 1.5 x the 10 % limit over the whole drop with the default tangent strain limiting.

    With up to 300 sweeps a round (its default): 0.115 measured (0.77 with the rounds'
    Jacobi strain limiting, whose corrections of the springs across the edge contact
    undoes; with 100 sweeps 0.171 at the landing, 0.132 over the last 3 s).
    """
    assert _table_strain(16, levels=5) < 1.5 * 0.1
    assert _table_strain(16, levels=5, contact_strain='jacobi') > 0.5


def test_strain_limiting_along_a_moving_table_holds_its_edge():
    """
    The tangent strain limiting moves points along moving bodies' surfaces too.

    0.105 measured with the default tangent strain limiting, 0.43 with the rounds' Jacobi
    strain limiting (``tools/table_flaps.py multigrid --levels 4 --rising 0.05``).
    """
    assert _table_strain(16, levels=4, rising=0.05) < 1.5 * 0.1
    assert _table_strain(16, levels=4, rising=0.05, contact_strain='jacobi') > 0.3


def _about_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize('moving', [False, True])
def test_the_tangent_strain_limiting_keeps_a_spring_across_an_edge_on_its_faces(moving):
    """
    A spring from a table's top over its edge to its side face, 41 % over its limit.

    Shortened to its limit (within the tolerance) with its ends still on their faces;
    moving both ends along the spring instead, into the table, would leave contact to undo
    the correction. The table is a static box, or a moving body turned 0.5 rad about z
    (where it is at the end of the step). A spring of a free point is corrected as
    Jacobi's would.
    """
    margin = 0.002
    centre, half = np.array(TABLE[:3]), np.array(TABLE[3:])
    top, side = half[2] + margin, half[0] + margin      # in the table's frame
    ends = np.array([[side - 0.012, 0.0, top], [side, 0.0, top - 0.012]])
    rotation = _about_z(0.5) if moving else np.eye(3)
    control = Control(ClothBuilder(resolution=(3, 3), level_count=1).finalize())
    if moving:
        scene = make_scene(margin=margin)
        control.bodies.add('table', 'box', half)
        control.bodies.set_pose('table', rotation, centre - 0.05)   # where it came from
        control.bodies.commit()
        control.bodies.set_pose('table', rotation, centre)
    else:
        scene = make_scene(boxes=[TABLE], margin=margin)
    bodies = control.bodies.packed()
    assert len(bodies) == int(moving)
    start = (ends @ rotation.T + centre).T[:, None, :].copy()
    q = start.copy()
    rest = np.full(12, 0.012 / 1.1)
    qd, dv = np.zeros_like(q), np.zeros_like(q)
    hold = np.zeros((1, 2), dtype=np.int8)
    sweeps = contact_strain.tangent_strain_limit(
        q, qd, dv, rest, hold, scene.planes, scene.boxes, scene.spheres, bodies, margin,
        scene.friction, 0.1, 100, 0.005, DT, 1.0, True)
    assert 1 <= sweeps < 100
    length = np.linalg.norm(q[:, 0, 1] - q[:, 0, 0])
    assert 0.012 * (1.0 - 1e-9) <= length <= 0.012 * 1.005
    local = (q[:, 0, :].T - centre) @ rotation
    assert local[0, 2] == pytest.approx(top, abs=1e-12)     # still on the top
    assert local[1, 0] == pytest.approx(side, abs=1e-12)    # still on the side face
    assert np.allclose(qd * DT, q - start, atol=1e-15)
    # in the air the two ends move along the spring, half the excess each (times the
    # relaxation: over-relaxed, the spring is left shorter than its limit)
    for relaxation, left, right in ((1.0, 0.004, 0.016), (1.5, 0.006, 0.014)):
        free = np.array([[[0.0, 0.02]], [[0.0, 0.0]], [[1.0, 1.0]]])
        contact_strain.tangent_strain_limit(
            free, np.zeros_like(free), np.zeros_like(free), rest, hold, scene.planes,
            scene.boxes, scene.spheres, bodies, margin, scene.friction, 0.1, 1, 0.005, DT,
            relaxation, True)
        assert free[0, 0, 0] == pytest.approx(left) and free[0, 0, 1] == pytest.approx(right)


@pytest.mark.parametrize('kind, size', [('box', (0.3, 0.2, 0.05)), ('sphere', (0.1,)),
                                        ('capsule', (0.01, 0.2))])
def test_no_point_on_or_in_a_grown_body_is_taken_as_far_from_it(kind, size):
    """
    The tangent sweeps skip a body's frame change for points outside a sphere round it.

    That sphere must hold the body grown by the margin and the band: a box's corners grow
    along each axis (a sphere of its half diagonal plus the growth left them out, and a
    rising table's drop at 129 x 129 came out different). Points at the grown box's
    corners and edges, on a sphere's and a capsule's grown surface and at a capsule's
    tips, under a turned and moved pose.
    """
    grow = 0.002 + contact_strain.BAND
    control = Control(ClothBuilder(resolution=(3, 3), level_count=1).finalize())
    control.bodies.add('body', kind, list(size))
    rotation = _about_z(0.7) @ np.array([[1.0, 0.0, 0.0], [0.0, 0.6, -0.8], [0.0, 0.8, 0.6]])
    control.bodies.set_pose('body', rotation, (0.4, -0.2, 0.9))
    control.bodies.commit()
    row = control.bodies.packed()[0]
    rng = np.random.default_rng(3)
    if kind == 'box':
        half = np.array(size) + grow
        corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
        local = np.concatenate([corners * half, corners * half * rng.uniform(0, 1, (8, 3))])
    else:
        normals = rng.normal(size=(200, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        local = normals * (size[0] + grow)
        if kind == 'capsule':       # the core runs along the body's z
            local[:, 2] += np.where(local[:, 2] > 0, size[1], -size[1])
    for point in local @ rotation.T + (0.4, -0.2, 0.9):
        assert not contact_strain._far_from(row, *point, grow)
    assert contact_strain._far_from(row, 10.0, 0.0, 0.0, grow)


def _stretched_sheet(n, stretch):
    """
    Lay a sheet of n x n points, 1 m a side, on the ground: stretched along x, last column pinned.

    Returns the tangent strain limiting's arguments up to the strain limit (10 %).
    """
    from hcloth_ros.core.kernels.layout import PINNED
    margin, spacing = 0.002, 1.0 / (n - 1)
    scene = make_scene(ground_z=0.0, margin=margin)
    rows, cols = np.meshgrid(np.arange(n), np.arange(n), indexing='ij')
    q = np.stack([cols * spacing * (1.0 + stretch), rows * spacing,
                  np.full((n, n), margin)]).astype(float)
    # stencil rest lengths: structural, diagonal, then the bending springs' two spacings
    rest = np.repeat([spacing, spacing * np.sqrt(2.0), 2.0 * spacing], 4)
    hold = np.zeros((n, n), dtype=np.int8)
    hold[:, -1] = PINNED
    return (q, np.zeros_like(q), np.zeros_like(q), rest, hold, scene.planes, scene.boxes,
            scene.spheres, np.zeros((0, 29)), margin, scene.friction, 0.1)


@pytest.mark.parametrize('n', [33, 65])
def test_tethers_pull_a_sheet_on_the_ground_to_its_pinned_edge_in_a_few_sweeps(n):
    """
    A sheet on the ground stretched 12 % along x (limit 10 %), its far column pinned.

    Gauss-Seidel sweeps pass the pinned edge's pull on one spring a sweep, each move shared
    by the spring's two ends: the sweeps grow with the square of the side (207 at 33 x 33,
    816 at 65 x 65). Tethered to the pinned points after the first sweeps, every point is
    within the limit of its anchor in one pass and the sweeps stay near 14. Either way
    every spring ends within its limit and tolerance and the sheet stays on the ground;
    with tethers the free edge ends where the limit puts it, 1.1 m from the pinned one
    (the sweeps alone stop at the tolerance, up to 5.5 mm short of that).
    """
    sweeps, edges = {}, {}
    for tethers in (False, True):
        args = _stretched_sheet(n, 0.12)
        q, qd = args[0], args[1]
        start = q.copy()
        sweeps[tethers] = contact_strain.tangent_strain_limit(
            *args, 10000, 0.005, DT, 1.5, tethers)
        assert sweeps[tethers] < 10000
        rest = 1.0 / (n - 1)
        for axis in (1, 2):                     # along columns and rows
            length = np.linalg.norm(np.diff(q, axis=axis), axis=0)
            assert length.max() <= rest * 1.1 * 1.005 * (1 + 1e-12)
        for diagonal in (q[:, 1:, 1:] - q[:, :-1, :-1], q[:, 1:, :-1] - q[:, :-1, 1:]):
            assert np.linalg.norm(diagonal, axis=0).max() <= \
                rest * np.sqrt(2.0) * 1.1 * 1.005 * (1 + 1e-12)
        assert np.all(q[2] == 0.002)            # on the ground's margin
        assert np.allclose(qd * DT, q - start, atol=1e-12)
        edges[tethers] = q[0, :, 0]
    assert np.all(np.abs(edges[True] - (1.12 - 1.1)) < 1e-9)
    assert np.all(np.abs(edges[False] - (1.12 - 1.1)) <= 1.1 * 0.005)
    assert sweeps[True] <= 20
    assert sweeps[False] > 10 * sweeps[True]


def test_a_point_takes_an_anchor_nearest_it_at_rest():
    """
    The anchors' propagation against every anchor tried: 200 random grids and anchor sets.

    The anchor a point takes is an anchor, its squared distance at rest is the one given,
    and it is at most 1 % farther than the nearest (the passes measured 0.47 % at most:
    vector propagation misses the nearest where it is reached only by a path that
    turns back).
    """
    rng = np.random.default_rng(1)
    for _ in range(200):
        rows, cols = rng.integers(5, 60, size=2)
        chosen = np.stack([rng.integers(0, rows, 6), rng.integers(0, cols, 6)], axis=1)
        anchor = np.full((2, rows, cols), -1, dtype=np.int64)
        anchor[:, chosen[:, 0], chosen[:, 1]] = chosen.T
        row_step, col_step = 0.01 * rng.uniform(0.5, 2.0, size=2)
        squared = np.empty((rows, cols))
        contact_strain._nearest_anchors(anchor, row_step, col_step, squared)
        r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing='ij')
        assert np.all(np.isin(anchor[0] * cols + anchor[1], chosen[:, 0] * cols + chosen[:, 1]))
        taken = ((r - anchor[0]) * row_step) ** 2 + ((c - anchor[1]) * col_step) ** 2
        assert np.allclose(taken, squared, rtol=1e-12, atol=0.0)
        nearest = np.min([((r - a) * row_step) ** 2 + ((c - b) * col_step) ** 2
                          for a, b in chosen], axis=0)
        assert np.all(squared <= nearest * 1.01 ** 2)


@pytest.mark.parametrize('strain', ['jacobi', 'tangent'])
def test_a_finger_pressing_the_cloth_into_the_ground_drags_it_within_the_limit(strain):
    """
    A finger pressing the cloth into the ground: the contact bench's scene at 65 x 65.

    A capsule reaching 2 mm below the cloth on the
    ground drags it 0.2 m along x in a second. Tangent strain limiting leaves the points it
    presses where the finger's friction holds them (``_held``) and corrects their free
    neighbours instead: largest strain 0.105 over the run (10 % limit, 0.5 % tolerance);
    Jacobi moves both ends, the finger puts the pressed one back every round: 0.35 (the
    tangent kernel before it left pressed points movable: 0.65). Either way the cloth goes
    with the finger (0.18 m on average).
    """
    from hcloth_ros.bench.self_contact import _move_finger, scene_setup
    model, state, control = scene_setup(65, 'finger')
    solver = make_solver('multigrid', model, contact_rounds=16, contact_strain=strain)
    top = model.level_count - 1
    start = state.q[top][0].copy()
    worst = 0.0
    for i in range(61):
        _move_finger(control, i)
        report = solver.step(state, control, DT)
        assert report.ok
        worst = max(worst, report.max_strain)
    assert 0.15 < np.mean(state.q[top][0] - start) < 0.21
    if strain == 'tangent':
        assert worst < 0.11             # the limit and its tolerance
    else:
        assert worst > 0.15             # issue 10's bound: 1.5 times the limit


def test_an_unknown_contact_strain_is_refused():
    model = ClothBuilder(resolution=(5, 5), level_count=2).finalize()
    with pytest.raises(ValueError, match="contact_strain must be one of .*'gauss'"):
        make_solver('multigrid', model, contact_strain='gauss')


@pytest.mark.parametrize('relaxation', [0.9, 2.0, float('nan')])
def test_a_contact_relaxation_outside_one_to_two_is_refused(relaxation):
    model = ClothBuilder(resolution=(5, 5), level_count=2).finalize()
    with pytest.raises(ValueError, match=r'contact_relaxation must be in \[1, 2\)'):
        make_solver('multigrid', model, contact_relaxation=relaxation)


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


def _reports_of(solver):
    """Wrap ``solver.step`` to keep the report of every call; return the list."""
    reports, inner = [], solver.step

    def step(*args, **kwargs):
        report = inner(*args, **kwargs)
        reports.append((report.ok, report.max_strain, report.seconds))
        return report
    solver.step = step
    return reports


def test_a_ticks_report_holds_its_largest_strain_and_all_its_time():
    """
    A report for several steps: the last one's, its largest strain, every try's time.

    The thrown fold (``tools/thrown_fold.py``) as the node steps it: the whole step is
    refused, the two half steps go through, the first at 0.36 and the second at 0.22
    (2026-11-30): ``max_strain`` is the end's and ``peak_strain`` the first half's, which
    the tick's report showed nowhere before; ``seconds`` holds the refused try's time too.
    A tick of four substeps (``Simulation.advance``) reports the same way.
    """
    model, state, solver = load_tool('thrown_fold').thrown(5.0, 0.5)
    calls = _reports_of(solver)
    report, taken = step_with_retries(solver, state, Control(model), 1.0 / 60.0)
    assert taken == 2 and [ok for ok, _, _ in calls] == [False, True, True]
    assert report.max_strain == calls[-1][1]
    assert report.peak_strain == max(calls[1][1], calls[2][1]) > report.max_strain + 0.1
    assert report.seconds == pytest.approx(sum(s for _, _, s in calls), rel=1e-12)
    sim = Simulation.build(params.resolve({'solver.substeps': 4}))
    calls = _reports_of(sim.solver)
    for _ in range(5):
        calls.clear()
        report = sim.advance()
        assert report.ok and len(calls) == 4
        assert report.max_strain == calls[-1][1]
        assert report.peak_strain == max(strain for _, strain, _ in calls)
        assert report.seconds == pytest.approx(sum(s for _, _, s in calls), rel=1e-12)


class _Scripted:
    """
    A solver whose steps' outcomes are given: what ``step_with_retries`` does with them.

    Each call takes the next ``(ok, strain)`` of ``script`` for the step's length; an
    accepted step advances the state's time and writes ``strain`` into its positions (so
    that the result shows which try it came from); a refused one is ``stretched``.
    """

    retry_strain = 0.5
    self_contact = None

    def __init__(self, script):
        self.script, self.calls = list(script), []

    def step(self, state, control, dt):
        ok, strain = self.script.pop(0)
        self.calls.append((dt, ok, self.retry_strain))
        if not ok:
            return StepReport(False, f'strain {strain} > retry_strain: step refused',
                              max_strain=strain, stretched=True, seconds=0.001)
        state.time += dt
        state.q[-1][...] = strain
        return StepReport(True, max_strain=strain, seconds=0.001)

    def checkpoint(self):
        return None

    def restore(self, checkpoint):
        pass


def test_a_step_whose_smallest_retries_stretch_further_is_taken_whole_after_all():
    """
    The whole step refused as stretched (0.6), 2 and 4 steps too, the 8 reaching 1.3.

    Kept: the whole step, taken again with its stretch allowed (n = 1, ``refused`` and
    ``smaller_strain`` in its report, the time of every try); where the 8 steps stay below
    the whole step's 0.6 they are kept. The fold demo's scene solved on 65 x 65 (seed 6,
    a held corner lowered onto the bottom layer on the ground) stretched to 0.60 in one
    step and to 1.36 in 8, whose 16 edges through triangles stayed (README, self-contact's
    known limits).
    """
    model = ClothBuilder(resolution=(5, 5), level_count=1).finalize()
    for smallest, kept in ((1.3, 'whole'), (0.45, 'eight')):
        script = [(False, 0.6), (False, 0.7), (False, 0.8)] + [(True, 0.4)] * 7 + \
            [(True, smallest)] + [(True, 0.6)]
        solver, state = _Scripted(script), State.at_rest(model)
        report, taken = step_with_retries(solver, state, Control(model), DT)
        assert report.ok and state.time == pytest.approx(DT) and retried(report, taken)
        if kept == 'whole':
            assert taken == 1 and report.max_strain == 0.6 and np.all(state.q[-1] == 0.6)
            assert report.extra['smaller_strain'] == 1.3
            assert report.extra['refused'].startswith('strain 0.6')
            assert solver.calls[-1] == (DT, True, None)     # whole, its stretch allowed
            assert report.seconds == pytest.approx(0.001 * 12)
        else:
            assert taken == 8 and report.peak_strain == 0.45 and np.all(state.q[-1] == 0.45)
            assert 'smaller_strain' not in report.extra and len(solver.calls) == 11
        assert solver.retry_strain == 0.5
    plain = step_with_retries(_Scripted([(True, 0.2)]), State.at_rest(model), Control(model), DT)
    assert not retried(*plain)


def test_the_multigrid_solver_takes_a_step_again_as_it_took_it_after_a_restore():
    """
    ``checkpoint`` keeps BDF2's history: the same step from the same state, bit for bit.

    The thrown fold's first step accepted; then three smaller steps change the history;
    restored (state and solver), the step comes out as the first time. Without the history
    in the checkpoint the step ran as backward Euler (the history was the smaller
    steps'), 0.30 where the first had 0.60 on the fold demo's solved scene.
    """
    model, state, solver = load_tool('thrown_fold').thrown(2.0, None)
    control = Control(model)
    for _ in range(2):          # two steps: the next is BDF2
        assert solver.step(state, control, DT).ok
    start, kept = state.copy(), solver.checkpoint()
    first = solver.step(state, control, DT)
    after = [q.copy() for q in state.q]
    for _ in range(3):
        solver.step(state, control, DT / 8)
    state.assign(start)
    solver.restore(kept)
    again = solver.step(state, control, DT)
    assert first.ok and again.ok and again.max_strain == first.max_strain
    assert all(np.array_equal(a, b) for a, b in zip(after, state.q))


def test_retries_below_the_strain_limit_are_warned_of():
    """
    A retry strain not above the strain limit would redo steps the limit accepts.

    Strain limiting leaves springs up to its limit: with ``retry_strain`` at or below it,
    a contact step that stretches a spring of a slack cloth within the limit is taken
    again in up to 14 smaller steps. Without self-contact nothing is retried for strain.
    """
    model = ClothBuilder(resolution=(9, 9), level_count=2).finalize()

    def warning(**options):
        return retry_warning(make_solver('multigrid', model, **options))
    assert warning(thickness=0.004, retry_strain=0.5) is None     # the node's defaults
    assert warning(thickness=0.004, retry_strain=0.2, strain_limit=None) is None
    assert warning(thickness=0.004) is None                         # no retries
    assert warning(retry_strain=0.05) is None                       # no self-contact
    for retry in (0.05, 0.1):
        text = warning(thickness=0.004, retry_strain=retry)
        assert f'solver.retry_strain {retry:g} is not above solver.strain_limit 0.1' in text
    solver = make_solver('multigrid', model, thickness=0.004, retry_strain=0.5)
    solver.strain_limit = 0.6       # as the node sets it at run time
    assert 'is not above solver.strain_limit 0.6' in retry_warning(solver)
