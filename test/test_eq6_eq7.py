"""
Eq. 6 and eq. 7 of the paper against their definitions, built densely in numpy.

Eq. 6 is two Jacobi sweeps, started from dv = 0, of the linearised backward-Euler system
(paper eq. 3) ``A dv = b`` with

    A = M - h^2 J,   J_ij = k_ij I (spring (i, j)),   J_ii = -K_i I,   K_i = sum_j k_ij,
    b = h f~,        f~_i = f_i + h sum_j k_ij (v_j - v_i)          (eq. 4: b = h (f + h J v))

so  dv1 = D^-1 b  and  dv2 = D^-1 (b - (A - D) dv1),  D = diag(A) = m_i + h^2 K_i.
Held (pinned / driven) points are Dirichlet rows: their row of A becomes the identity and
their right-hand side their prescribed change (pinned: -v, so the new velocity is 0).

Everything below is written from these definitions (dense 3n x 3n matrices, one spring
list made from the 12-direction stencil), independently of the numba kernels, and
compared with one step of the solvers. The arithmetic is the same up to the order of
summation, so results agree to rounding: 1e-12 relative to the size of the velocities
(~1e4 ulp of slack for sums of a dozen O(1e3) terms).
"""

from hcloth_ros.core import ClothBuilder, Control, make_solver, State
from hcloth_ros.core import kernels
from hcloth_ros.core.model import STENCIL_DC, STENCIL_DR
import numpy as np
import pytest

H = 1.0 / 60.0
RTOL = 1e-12


class DenseLevel:
    """One grid level as a spring list and the dense matrices of the paper."""

    def __init__(self, model, k):
        lv = model.level(k)
        self.lv = lv
        self.n = lv.rows * lv.cols
        self.mass = lv.mass.ravel().copy()
        self.springs = []           # (i, j, k_ij, L_ij), every spring once
        for s in range(0, 12, 2):
            dr, dc = STENCIL_DR[s], STENCIL_DC[s]
            # the odd entry is the opposite direction of the same spring kind
            assert (STENCIL_DR[s + 1], STENCIL_DC[s + 1]) == (-dr, -dc)
            assert lv.stiffness[s] == lv.stiffness[s + 1] and lv.rest[s] == lv.rest[s + 1]
            for r in range(lv.rows):
                for c in range(lv.cols):
                    rr, cc = r + dr, c + dc
                    if 0 <= rr < lv.rows and 0 <= cc < lv.cols:
                        self.springs.append((r * lv.cols + c, rr * lv.cols + cc,
                                             lv.stiffness[s], lv.rest[s]))
        kmat = np.zeros((self.n, self.n))
        for i, j, kij, _ in self.springs:
            assert kmat[i, j] == 0.0      # at most one spring per pair of points
            kmat[i, j] = kmat[j, i] = kij
        self.kmat = kmat
        self.ksum = kmat.sum(axis=1)
        # the paper's Jacobian approximation, 3n x 3n, index 3 i + d
        self.jac = np.kron(kmat - np.diag(self.ksum), np.eye(3))

    def forces(self, x, contraction):
        """
        Spring forces with contraction resistance, shape (n, 3).

        A compressed spring pushes back with c times its force.
        """
        f = np.zeros((self.n, 3))
        for i, j, kij, rest in self.springs:
            d = x[j] - x[i]
            length = np.linalg.norm(d)
            stretch = length - rest
            k = kij if stretch >= 0 else kij * contraction
            fij = k * stretch * d / length
            f[i] += fij
            f[j] -= fij
        return f

    def f_tilde(self, x, v, h, gravity, literal):
        """Eq. 4: f~ = f + h J v, with m g inside f for the literal mode."""
        f = self.forces(x, self.lv.contraction)
        if literal:
            f = f + self.mass[:, None] * gravity[None, :]
        return f + h * (self.jac @ v.ravel()).reshape(-1, 3)

    def system(self, h):
        return np.kron(np.diag(self.mass), np.eye(3)) - h * h * self.jac


def two_jacobi_sweeps(a_mat, b, held, held_value):
    """
    Two Jacobi sweeps from 0 on ``a_mat x = b`` with Dirichlet rows for ``held`` points.

    ``held`` is an index array of points; their value is ``held_value``, shape (len, 3).
    """
    a_mat = a_mat.copy()
    b = b.copy()
    for m, i in enumerate(held):
        rows = slice(3 * i, 3 * i + 3)
        a_mat[rows, :] = 0.0
        a_mat[rows, rows] = np.eye(3)
        b[rows] = held_value[m]
    d = np.diag(a_mat)
    off = a_mat - np.diag(d)
    x1 = b / d
    x2 = (b - off @ x1) / d
    return x1, x2


def grid_xv(state, k):
    return state.points(k), state.velocities(k)


def perturbed_model(levels, contraction):
    return ClothBuilder(width=0.8, height=0.6, resolution=(3, 3), level_count=levels,
                        total_mass=0.2, k_struct=1000.0, k_shear=800.0, k_bend=100.0,
                        contraction=contraction).finalize()


def perturb(model, state, k, rng, amp_x=0.02, amp_v=0.3, only_inserted=False):
    lv = model.level(k)
    mask = np.ones((lv.rows, lv.cols), bool)
    if only_inserted:
        mask[0::2, 0::2] = False
    state.q[k] += amp_x * rng.standard_normal(state.q[k].shape) * mask
    state.qd[k] += amp_v * rng.standard_normal(state.qd[k].shape) * mask


def scale_of(*arrays):
    return max(np.max(np.abs(a)) for a in arrays)


# --- eq. 6 ---------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def eq6_case():
    model = perturbed_model(1, (0.5,))
    rng = np.random.default_rng(1234)
    state = State.at_rest(model)
    perturb(model, state, 0, rng)
    return model, state


def test_reference_matrices_match_the_model(eq6_case):
    # K_i of the model is the Jacobian diagonal built from the spring list, and the
    # numpy spring forces agree with the kernel's (same formula, summation order aside).
    model, state = eq6_case
    ref = DenseLevel(model, 0)
    np.testing.assert_allclose(ref.ksum, model.level(0).stiffness_sum.ravel(), rtol=1e-15)
    f = np.zeros_like(state.q[0])
    lv = model.level(0)
    kernels.spring_forces(state.q[0], lv.rest, lv.stiffness, lv.contraction, f)
    fref = ref.forces(state.points(0), lv.contraction)
    np.testing.assert_allclose(f.reshape(3, -1).T, fref, rtol=0,
                               atol=RTOL * np.max(np.abs(fref)))
    # the random perturbation must have compressed some springs, or contraction c = 0.5
    # would be untested
    x = state.points(0)
    compressed = sum(np.linalg.norm(x[j] - x[i]) < rest for i, j, _, rest in ref.springs)
    assert 0 < compressed < len(ref.springs)
    # and springs are internal forces: they sum to zero (1e-12 of the largest force)
    assert np.max(np.abs(fref.sum(axis=0))) < RTOL * np.max(np.abs(fref)) * ref.n


@pytest.mark.parametrize('external', ['literal', 'exact'])
def test_eq6_is_two_jacobi_sweeps(eq6_case, external):
    model, state0 = eq6_case
    literal = external == 'literal'
    ref = DenseLevel(model, 0)
    g = model.gravity
    x, v = grid_xv(state0, 0)
    pinned = 4                       # the centre point of the 3x3 grid, id 4 at level 0
    driven = 8                       # a corner, driven to a target by set_target
    assert model.level(0).id_to_grid[pinned] == 4 and model.level(0).id_to_grid[driven] == 8
    held = np.array([pinned, driven])
    target = x[driven] + np.array([0.01, 0.02, -0.03])
    # prescribed changes: a pinned point stops (new velocity exactly zero); a driven one
    # gets the velocity that reaches its target at the end of the step
    presc = np.stack([-v[pinned], (target - x[driven]) / H - v[driven]])

    a_mat = ref.system(H)
    if literal:
        # gravity inside f~, through the filter (paper as written)
        b = H * ref.f_tilde(x, v, H, g, True).ravel()
        dv1, dv2 = two_jacobi_sweeps(a_mat, b, held, presc)
    else:
        # Exact external part: A (h g 1) = M h g because every row of the paper's J
        # sums to zero (J_ii = -sum_j k_ij), so A dv = h f~_spring + h M g is the same
        # system as A y = h f~_spring for y = dv - h g. The kernel runs the two sweeps on
        # y, with held points entering as their prescribed change minus h g.
        b = H * ref.f_tilde(x, v, H, g, False).ravel()
        y1, y2 = two_jacobi_sweeps(a_mat, b, held, presc - H * g)
        dv1, dv2 = y1 + np.tile(H * g, ref.n), y2 + np.tile(H * g, ref.n)
        # (the claim A (h g 1) = M h g itself)
        hg = np.tile(H * g, ref.n)
        np.testing.assert_allclose(a_mat @ hg, np.repeat(ref.mass, 3) * hg, rtol=0,
                                   atol=1e-12 * np.max(np.abs(a_mat)) * H * 9.81)
    dv2 = dv2.reshape(-1, 3)
    dv1 = dv1.reshape(-1, 3)

    # cross-check of the reference: the closed form of eq. 6 (method.md section 2), with
    # held neighbours entering as their prescribed change, is the same thing point by point
    if literal:
        ft = ref.f_tilde(x, v, H, g, True)
        dinv = 1.0 / (ref.mass + H * H * ref.ksum)
        first = H * ft * dinv[:, None]
        first[held] = presc
        closed = (H * ft + H * H * ref.kmat @ first) * dinv[:, None]
        free = np.setdiff1d(np.arange(ref.n), held)
        np.testing.assert_allclose(closed[free], dv2[free], rtol=0,
                                   atol=RTOL * scale_of(dv2))

    state = state0.copy()
    control = Control(model)
    control.pin([pinned])
    control.set_target(driven, target, state)
    solver = make_solver('approx', model, level=0, external=external, strain_limit=None)
    report = solver.step(state, control, H)
    assert report.ok, report.reason
    x_new, v_new = grid_xv(state, 0)
    scale = scale_of(v, dv2)
    free = np.setdiff1d(np.arange(ref.n), held)
    np.testing.assert_allclose(v_new[free], v[free] + dv2[free], rtol=0, atol=RTOL * scale)
    np.testing.assert_allclose(v_new[free] - v[free], dv2[free], rtol=0, atol=RTOL * scale)
    # semi-implicit order: x += h v_new
    np.testing.assert_allclose(x_new[free], x[free] + H * (v[free] + dv2[free]), rtol=0,
                               atol=RTOL * max(scale_of(x), scale))
    # the pinned point: v + (-v) is exactly 0, x + h * 0 is exactly x
    assert np.all(v_new[pinned] == 0.0)
    assert np.array_equal(x_new[pinned], x[pinned])
    # the driven point reaches its target (a few ulp of |x| ~ 1 m)
    np.testing.assert_allclose(x_new[driven], target, rtol=0, atol=1e-12)
    # the second sweep matters: it differs from the first by far more than the tolerance
    # (otherwise this test could not tell one sweep from two)
    assert np.max(np.abs(dv2[free] - dv1[free])) > 1e3 * RTOL * scale
    assert state.time == pytest.approx(H, rel=1e-15)


def test_eq6_exact_mode_free_fall_of_a_flat_cloth():
    # A flat cloth at rest with no pins has f = 0 and v = 0, so the spring part of the
    # exact mode is zero and every point gains exactly h g (the external part is not
    # filtered; only rounding of |x_j - x_i| - L_ij ~ 1e-16 m leaks in, times k / m * h
    # ~ 1e-15 m/s). The literal mode filters the same uniform load: point i gets
    # h g (m_i + h^2 sum_j k_ij m_j / (m_j + h^2 K_j)) / (m_i + h^2 K_i), less than h g
    # because m_j / (m_j + h^2 K_j) < 1 (paper section III: the cloth falls slowly).
    model = perturbed_model(1, None)
    g = model.gravity
    for external in ('exact', 'literal'):
        state = State.at_rest(model)
        solver = make_solver('approx', model, level=0, external=external, strain_limit=None)
        assert solver.step(state, Control(model), H).ok
        v_new = state.velocities(0)
        if external == 'exact':
            np.testing.assert_allclose(v_new, np.tile(H * g, (9, 1)), rtol=0,
                                       atol=1e-15 * 9.81)
        else:
            ref = DenseLevel(model, 0)
            dinv = 1.0 / (ref.mass + H * H * ref.ksum)
            expected = H * (ref.mass + H * H * ref.kmat @ (ref.mass * dinv)) * dinv
            np.testing.assert_allclose(v_new[:, 2], expected * g[2], rtol=1e-12)
            assert np.all(v_new[:, 2] > H * g[2])      # falls slower than g


# --- eq. 7 ---------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def eq7_case():
    model = perturbed_model(2, (0.5, 0.7))
    rng = np.random.default_rng(99)
    state = State.at_rest(model)
    perturb(model, state, 0, rng)
    # level 1 starts consistent with level 0 (inherited points equal, inserted points
    # at the midpoints) plus its own detail on the inserted points
    kernels.prolong(state.q[0], state.q[1])
    kernels.prolong(state.qd[0], state.qd[1])
    perturb(model, state, 1, rng, amp_x=0.01, amp_v=0.2, only_inserted=True)
    return model, state


def _eq6_reference(model, state, k, held_ids, literal):
    """Level k's eq. 6 velocity change (n, 3) with the given level-k ids pinned."""
    ref = DenseLevel(model, k)
    g = model.gravity
    x, v = grid_xv(state, k)
    held = model.level(k).id_to_grid[np.asarray(held_ids)]
    presc = -v[held]
    b = H * ref.f_tilde(x, v, H, g, literal).ravel()
    if literal:
        return two_jacobi_sweeps(ref.system(H), b, held, presc)[1].reshape(-1, 3)
    y2 = two_jacobi_sweeps(ref.system(H), b, held, presc - H * g)[1]
    return (y2 + np.tile(H * g, ref.n)).reshape(-1, 3)


@pytest.mark.parametrize('external', ['literal', 'exact'])
def test_eq7_on_inserted_points(eq7_case, external):
    model, state0 = eq7_case
    literal = external == 'literal'
    g = model.gravity
    l0, l1 = model.level(0), model.level(1)
    n0 = l0.point_count
    inserted_pin = n0                       # the first id inserted by level 1
    pins = [0, inserted_pin]
    anchor = model.anchor(inserted_pin)
    # level 0 holds the pins that exist there and the anchor of the inserted one
    dv0 = _eq6_reference(model, state0, 0, [0, anchor], literal)

    state = state0.copy()
    control = Control(model)
    control.pin(pins)
    solver = make_solver('hierarchical', model, external=external, strain_limit=None)
    report = solver.step(state, control, H)
    assert report.ok, report.reason
    assert report.levels == (0, 1)

    # level 0 is plain eq. 6 (step S of Table 1)
    x0, v0 = grid_xv(state0, 0)
    np.testing.assert_allclose(state.velocities(0), v0 + dv0, rtol=0,
                               atol=RTOL * scale_of(v0, dv0))

    # dv_app by id: level-0 change for inherited ids, mean over the two parents for
    # inserted ones (paper section IV); then back to level-1 grid order
    dv0_id = dv0[l0.id_to_grid]
    dv_app_id = np.zeros((l1.point_count, 3))
    dv_app_id[:n0] = dv0_id
    par = model.parents[n0:l1.point_count]
    dv_app_id[n0:] = 0.5 * (dv0_id[par[:, 0]] + dv0_id[par[:, 1]])
    dv_app = dv_app_id[l1.grid_to_id.ravel()]

    ref = DenseLevel(model, 1)
    x1, v1 = grid_xv(state0, 1)
    held = {int(l1.id_to_grid[p]): -v1[l1.id_to_grid[p]] for p in pins}
    # a held neighbour enters with its own prescribed change, not the estimate
    src = dv_app.copy()
    for i, presc in held.items():
        src[i] = presc
    ext = np.zeros(3) if literal else H * g
    ft = ref.f_tilde(x1, v1, H, g, literal)
    # eq. 7: dv_i = (h f~_i + h^2 sum_j k_ij dv_app_j) / (m_i + h^2 K_i); in the exact
    # mode h g is taken out of every neighbour's change and added back to the result,
    # so the external part is counted once
    dv1 = (H * ft + H * H * ref.kmat @ (src - ext)) / (ref.mass + H * H * ref.ksum)[:, None]
    dv1 += ext

    x1_new, v1_new = grid_xv(state, 1)
    inserted = l1.id_to_grid[np.arange(n0, l1.point_count)]
    free_inserted = np.array([i for i in inserted if i not in held])
    assert len(free_inserted) == l1.point_count - n0 - 1
    scale = scale_of(v1, dv1)
    np.testing.assert_allclose(v1_new[free_inserted], v1[free_inserted] + dv1[free_inserted],
                               rtol=0, atol=RTOL * scale)
    np.testing.assert_allclose(x1_new[free_inserted],
                               x1[free_inserted] + H * (v1[free_inserted]
                                                        + dv1[free_inserted]),
                               rtol=0, atol=RTOL * max(scale, scale_of(x1)))
    # eq. 7 uses the coarse estimate: with the free neighbours' estimate set to zero the
    # result would differ by far more than the tolerance (so this test does see dv_app)
    is_held = np.isin(np.arange(ref.n), list(held))[:, None]
    blind = (H * ft + H * H * ref.kmat @ (np.where(is_held, src, ext) - ext)) \
        / (ref.mass + H * H * ref.ksum)[:, None] + ext
    assert np.max(np.abs(blind - dv1)[free_inserted]) > 1e3 * RTOL * scale

    # constraint C: inherited points take level 0's new state, bit for bit
    assert np.array_equal(state.q[1][:, 0::2, 0::2], state.q[0])
    assert np.array_equal(state.qd[1][:, 0::2, 0::2], state.qd[0])
    # the pinned inserted point and its anchor hold exactly
    gi = l1.id_to_grid[inserted_pin]
    assert np.array_equal(x1_new[gi], x1[gi]) and np.all(v1_new[gi] == 0.0)
    ga = l0.id_to_grid[anchor]
    assert np.array_equal(state.points(0)[ga], x0[ga])
