"""
The backward-Euler reference (``make_solver('implicit', ...)``).

Convergence to its tolerance, the backward-Euler residual, exact free fall and stability
at large steps.
"""

from hcloth_ros.core import ClothBuilder, Control, make_solver, State
from hcloth_ros.core import kernels
import numpy as np
import pytest

H = 1.0 / 30.0


def hanging_model(contraction=None):
    # 5 x 5 points, 0.1 kg, stiff springs: h^2 K / m ~ 1.5e4 at h = 1/30, far beyond the
    # explicit limit (see test_stable_at_large_step_with_stiff_springs)
    return ClothBuilder(width=0.5, height=0.5, resolution=(5, 5), level_count=1,
                        total_mass=0.1, k_struct=1e4, k_shear=1e4, k_bend=1e3,
                        contraction=contraction).finalize()


def pinned_corners(model):
    control = Control(model)
    control.pin([0, model.level(0).cols - 1])      # the two corners of row 0
    return control


@pytest.fixture(scope='module')
def swinging():
    """
    Return a cloth pinned at two corners, 5 steps into its swing.

    Springs are stretched and some compressed: the harder case for Newton.
    """
    model = hanging_model()
    control = pinned_corners(model)
    state = State.at_rest(model)
    pre = make_solver('implicit', model, tolerance=1e-10, max_newton=200, strain_limit=None)
    for _ in range(5):
        assert pre.step(state, control, H).ok
    return model, control, state


def one_step(model, control, state, **options):
    s = state.copy()
    report = make_solver('implicit', model, strain_limit=None, **options).step(s, control, H)
    assert report.ok, report.reason
    return s, report


def halving_errors(model, control, state, tol):
    """
    Return the position differences (m) of one step solved to ``tol`` and ``tol / 2``.

    Newton stops once its estimated remaining error, the last update h |dv|_inf times
    max(1, rho / (1 - rho)) with rho the observed contraction rate, is below tol
    (solvers._newton_done). Both results then lie within tol of the exact solution (the
    tighter one within tol / 2) and differ by less than tol. Reference: 1e-12 m. Returns
    ``(converged, one_iteration, halved, tol_vs_ref, half_vs_ref)``: whether all three
    solves converged, and the largest differences of a single Newton iteration from the
    reference, of the two tolerances from each other and of each from the reference.
    """
    s1, r1 = one_step(model, control, state, tolerance=tol)
    s2, r2 = one_step(model, control, state, tolerance=tol / 2)
    ref, rr = one_step(model, control, state, tolerance=1e-12, cg_rtol=1e-12,
                       max_newton=1000)
    s0, _ = one_step(model, control, state, tolerance=tol, max_newton=1)

    def gap(a, b):
        return np.max(np.abs(a.q[0] - b.q[0]))
    return (r1.converged and r2.converged and rr.converged, gap(s0, ref), gap(s1, s2),
            gap(s1, ref), gap(s2, ref))


def test_halving_the_tolerance_changes_less_than_the_tolerance(swinging):
    model, control, state = swinging
    converged, one_iteration, halved, tol_vs_ref, half_vs_ref = halving_errors(
        model, control, state, 1e-6)
    assert converged and one_iteration > 1e-5
    assert halved < 1e-6 and tol_vs_ref < 1e-6 and half_vs_ref < 0.5e-6


def test_halving_the_tolerance_on_a_stretched_cloth():
    # A cloth stretched by 5 % (what strain limiting at 10 % allows), slightly crumpled
    # out of plane, pinned at two corners, one step of 1/30 s.
    model = ClothBuilder(width=0.8, height=0.6, resolution=(4, 3), level_count=1,
                         total_mass=0.2).finalize()
    rng = np.random.default_rng(5)
    state = State.at_rest(model)
    state.q[0] *= np.array([1.05, 1.05, 1.0])[:, None, None]
    state.q[0][2] += 0.01 * rng.standard_normal(state.q[0][2].shape)
    control = Control(model)
    control.pin([0, 3])
    converged, one_iteration, halved, tol_vs_ref, half_vs_ref = halving_errors(
        model, control, state, 1e-4)
    assert converged and one_iteration > 1e-3
    assert halved < 1e-4 and tol_vs_ref < 1e-4 and half_vs_ref < 0.5e-4


@pytest.mark.parametrize('contraction', [1.0, 0.5])
def test_converged_step_satisfies_backward_euler(swinging, contraction):
    # Backward Euler: R(v+) = M (v+ - v) - h f(x + h v+) - h M g = 0 on free points.
    # Bound from the tolerance: the next Newton update d' = -A^-1 R would be no larger
    # than the last one (|d|_inf < tol / h, convergent iteration), so
    # |R|_inf = |A d'|_inf <= |A|_inf tol / h, and each row of A = M - h^2 J sums in
    # absolute value to at most m_i + 2 sqrt(3) h^2 K_i (a spring block
    # k (b I + (1-b) u u^T), 0 <= b < 1, has row sums <= sqrt(3) k; once on the diagonal,
    # once off it).
    _, _, state = swinging
    model = hanging_model(contraction=[contraction])
    control = pinned_corners(model)
    lv = model.level(0)
    tol = 1e-9
    s, report = one_step(model, control, state, tolerance=tol, max_newton=100)
    assert report.converged
    f = np.zeros_like(s.q[0])
    kernels.spring_forces(s.q[0], lv.rest, lv.stiffness, lv.contraction, f)
    g = model.gravity[:, None, None]
    # x+ = x + h v+ (what the solver committed)
    np.testing.assert_allclose(s.q[0], state.q[0] + H * s.qd[0], rtol=0, atol=1e-15)
    residual = lv.mass * (s.qd[0] - state.qd[0]) - H * f - H * lv.mass * g
    free = np.ones((lv.rows, lv.cols), bool)
    free[0, 0] = free[0, -1] = False
    bound = (lv.mass.max() + 2 * np.sqrt(3) * H * H * lv.stiffness_sum.max()) * tol / H
    # the bound is tight enough to see a wrong external force: h m g of the lightest
    # point is far above it
    assert bound < 0.05 * H * lv.mass.min() * 9.81
    assert np.max(np.abs(residual[:, free])) < bound
    # pinned points: exactly still
    assert np.array_equal(s.q[0][:, ~free], state.q[0][:, ~free])
    assert np.all(s.qd[0][:, ~free] == 0.0)


def test_free_fall_centre_of_mass_accelerates_at_g():
    # Springs are internal: sum_i f_i = 0, so summing backward Euler over all points gives
    # M_tot (V+ - V) = h M_tot g for the centre-of-mass velocity V, whatever the cloth
    # does. Newton keeps this up to CG's residual: 1^T (M - h^2 J) d = 1^T M d because J is
    # symmetric with zero row sums, so sum_i R_i after an iteration equals the sum of that
    # CG solve's residual (<= sqrt(3n) cg_rtol |R|_2, ~1e-12 here). After n steps:
    # V = V0 + n h g and X = X0 + n h V0 + h^2 g n (n + 1) / 2 (x += h v+), to 1e-9.
    rng = np.random.default_rng(11)
    model = ClothBuilder(width=0.5, height=0.4, resolution=(4, 3), level_count=1,
                         total_mass=0.1, contraction=[0.5]).finalize()
    lv = model.level(0)
    state = State.at_rest(model)
    state.q[0] += 0.02 * rng.standard_normal(state.q[0].shape)    # springs now act
    state.qd[0] += 0.3 * rng.standard_normal(state.qd[0].shape)
    mass_total = lv.mass.sum()

    def com(a):
        return (a * lv.mass).reshape(3, -1).sum(axis=1) / mass_total

    v0, x0 = com(state.qd[0]), com(state.q[0])
    h, n = 1.0 / 60.0, 30
    solver = make_solver('implicit', model, tolerance=1e-6, strain_limit=None)
    control = Control(model)
    for _ in range(n):
        report = solver.step(state, control, h)
        assert report.ok and report.converged
    g = model.gravity
    np.testing.assert_allclose(com(state.qd[0]), v0 + n * h * g, rtol=0, atol=1e-9)
    np.testing.assert_allclose(com(state.q[0]), x0 + n * h * v0 + h * h * g * n * (n + 1) / 2,
                               rtol=0, atol=1e-9)
    # not vacuous: the springs did move the points relative to each other
    rel = state.qd[0] - com(state.qd[0])[:, None, None]
    assert np.max(np.abs(rel)) > 1e-3


def test_stable_at_large_step_with_stiff_springs():
    # Backward Euler is unconditionally stable. Here h = 1/30 s is ~80x the explicit
    # limit 2 / omega_max (omega_max^2 ~ 2 K_i / m_i = 2 * 8.4e4 / 6.25e-3: dt < 4e-4 s).
    # The static strain of the cloth hanging from two corners is about
    # (M g / 2) / (k * ~2 springs) / spacing = 0.49 / 2e4 / 0.125 ~ 2e-4; the swing from
    # horizontal at most triples the load (pendulum tension 3 m g at the bottom): strain
    # stays below 1e-2 with margin. Energy (kinetic + gravity + elastic) can only decrease
    # under backward Euler (it is dissipative; exact for convex springs, which stretched
    # springs are), up to the Newton tolerance.
    model = hanging_model()
    lv = model.level(0)
    control = pinned_corners(model)
    state = State.at_rest(model)
    solver = make_solver('implicit', model, tolerance=1e-8, max_newton=100,
                         strain_limit=None)
    energies = []
    strains = []
    for _ in range(60):        # 2 s: the cloth falls, swings and settles
        report = solver.step(state, control, H)
        assert report.ok, report.reason
        assert np.all(np.isfinite(state.q[0])) and np.all(np.isfinite(state.qd[0]))
        strains.append(report.max_strain)
        energies.append(sum(kernels.energy(state.q[0], state.qd[0], lv.mass, lv.rest,
                                           lv.stiffness, lv.contraction, model.gravity)))
    assert max(strains) < 1e-2
    assert np.all(np.diff(energies) < 1e-9)
    # it really fell: the free bottom edge is ~ a cloth height below the pins
    assert state.q[0][2, -1, :].max() < 1.0 - 0.4
    # the explicit solver at the same step refuses within a few steps (blow-up detector)
    s2 = State.at_rest(model)
    explicit = make_solver('explicit', model, strain_limit=None)
    oks = [explicit.step(s2, control, H).ok for _ in range(3)]
    assert not all(oks)
