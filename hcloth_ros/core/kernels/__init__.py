"""
Every numba kernel of the engine, by the physics it computes.

Map: what the paper (or the method) writes, the kernels that compute it, their plain
reference forms (numpy, written from the formula) and the tests that hold them together,
in the order of a step:

held points' velocity change
    ``holds.prescribe``; reference inline in ``test_kernel_equivalence::test_prescribe``
spring force and eq. 4's filtered force ``f~ = f + h J v``
    ``springs.force_row``; ``ref_force``; every sweep test of ``test_kernel_equivalence``
eq. 6: two Jacobi sweeps of linearised backward Euler
    ``eq6.eq6_first_sweep``, ``eq6.eq6_second_sweep``; ``ref_eq6`` and the dense
    matrices ``DenseLevel``; ``test_kernel_equivalence::test_eq6_sweeps``,
    ``test_eq6_eq7::test_eq6_is_two_jacobi_sweeps``
Table 1, prolongation of the coarse velocity change
    ``eq7.prolong``; ``ref_prolong``, the parent table; ``test_hierarchy::test_prolong_*``,
    ``test_kernel_equivalence::test_eq7_level_and_prolong``
Table 1, constraint C and eq. 7 on inserted points
    ``eq7.eq7_level``; ``ref_eq7``, ``DenseLevel``;
    ``test_kernel_equivalence::test_eq7_level_and_prolong``,
    ``test_eq6_eq7::test_eq7_on_inserted_points``
symplectic Euler
    ``explicit.explicit_step``; ``ref_explicit``; ``test_kernel_equivalence::test_explicit_step``
backward Euler's system ``(M - h^2 J) dv = b`` and its CG solve
    ``implicit.system_apply``, ``implicit.system_diagonal``,
    ``implicit.conjugate_gradient``, ``implicit.spring_forces``; ``ref_system_apply``;
    ``test_kernel_equivalence::test_system_apply_and_cg``,
    ``test_implicit::test_converged_step_satisfies_backward_euler``
BDF2 (backward Euler on the first step): the step's anchor ``x^, v^``, the Newton residual
``M (v+ - v^) - beta F(x^ + beta v+, v+)`` (F: springs, spring damping, air drag, gravity)
and the new positions
    ``bdf2.anchor``, ``bdf2.newton_residual``, ``bdf2.new_positions``,
    ``bdf2.start_velocity``; ``test_multigrid::test_observed_order_when_the_step_halves``,
    ``test_multigrid::test_released_mid_swing_the_centre_of_mass_falls_at_g``,
    ``test_multigrid::test_air_drag_gives_the_terminal_velocity``
the Newton system ``M + beta D_air + beta^2 K + beta C`` on every level and its
V-cycle-preconditioned CG solve
    ``multigrid.assemble_hierarchy``, ``multigrid.multigrid_cg``, ``multigrid.inject``;
    the dense matrix of ``implicit.system_apply``;
    ``test_multigrid::test_stored_blocks_give_backward_eulers_matrix``,
    ``test_multigrid::test_v_cycle_preconditioner_on_a_33_grid``
refinement above the BDF2 level: eq. 7, then the coarse level's drift beyond ``h v+``
    ``eq7.eq7_level`` (``drift``); ``ref_prolong``;
    ``test_kernel_equivalence::test_eq7_level_adds_the_prolonged_drift``
strain limiting (Provot 1995)
    ``strain.strain_limit``; ``ref_strain_limit``; ``test_kernel_equivalence::test_strain_*``
contact with static obstacles
    ``contact.contact``; closed-form geometry; ``test_physics::test_cloth_dropped_on_*``
strain limiting in the contact rounds along the obstacles' surfaces (``contact_strain``)
    ``contact_strain.tangent_strain_limit``; ``test_contact_recovery::
    test_the_tangent_strain_limiting_keeps_a_spring_across_an_edge_on_its_faces``
contact with moving bodies (boxes, spheres, capsules; friction against their surface velocity)
    ``bodies.body_contact``; closed-form geometry and Coulomb's law; ``test_bodies``
self-contact (thickness, crossings during a step, friction between layers; layers lying
on each other carried from step to step; a level that comes back pushed out of itself)
    ``self_contact.self_contact``, ``self_contact.carry``, ``self_contact.settle``; a
    brute-force check over every point and triangle, Coulomb's law under a point's weight;
    ``test_self_contact``
strain and finiteness (the blow-up check), energy
    ``stats.strain_stats``, ``stats.energy``; inline; ``test_kernel_equivalence::
    test_strain_stats``, the energy checks of ``test_physics`` and ``test_implicit``
a level's positions for a message (float32, point-id order)
    ``export.points_by_id_f32``; ``State.points_by_id``;
    ``test_kernel_equivalence::test_points_by_id_f32``

The references live in ``test/test_kernel_equivalence.py`` (shifted numpy copies of the
grid) and ``test/test_eq6_eq7.py`` (dense 3n x 3n matrices of the paper's equations).

Shared pieces: :mod:`.layout` (the stencil, hold kinds, row chunks, the row update
``v += dv, x += h v``), :mod:`.springs` (a spring's vector and Hooke coefficient, the
force and the stencil sum along a row), :mod:`.jit` (flags and the source-keyed cache).

Threads: each per-step kernel runs one ``prange`` over row chunks (one chunk, so one
thread, on levels below ``layout.PAR_MIN_POINTS`` points). Strain limiting runs many
sweeps per call and starts a parallel region per sweep only on levels of several chunks.
"""

from types import SimpleNamespace

from hcloth_ros.core.kernels.jit import keyed_cache

with keyed_cache():
    from hcloth_ros.core.kernels.bdf2 import (anchor, new_positions, newton_residual,
                                              start_velocity)
    from hcloth_ros.core.kernels.bodies import body_contact
    from hcloth_ros.core.kernels.contact import contact
    from hcloth_ros.core.kernels.contact_strain import tangent_strain_limit
    from hcloth_ros.core.kernels.eq6 import eq6_first_sweep, eq6_second_sweep
    from hcloth_ros.core.kernels.eq7 import eq7_level, eq7_level_parallel, prolong
    from hcloth_ros.core.kernels.explicit import explicit_step
    from hcloth_ros.core.kernels.export import points_by_id_f32
    from hcloth_ros.core.kernels.holds import prescribe
    from hcloth_ros.core.kernels.implicit import (conjugate_gradient,
                                                  conjugate_gradient_parallel,
                                                  spring_forces, system_apply,
                                                  system_apply_parallel, system_diagonal)
    from hcloth_ros.core.kernels.layout import (chunk_count, DRIVEN, FREE, PAR_MIN_POINTS,
                                                PINNED, STENCIL_DC, STENCIL_DR,
                                                STENCIL_SIZE)
    from hcloth_ros.core.kernels.multigrid import assemble_hierarchy, inject, multigrid_cg
    from hcloth_ros.core.kernels.self_contact import self_contact, settle
    from hcloth_ros.core.kernels.stats import energy, strain_stats, strain_stats_parallel
    from hcloth_ros.core.kernels.strain import (excess_threshold, strain_limit,
                                                strain_limit_parallel)

KERNELS = ('anchor', 'assemble_hierarchy', 'body_contact', 'contact',
           'conjugate_gradient',
           'energy', 'eq6_first_sweep', 'eq6_second_sweep', 'eq7_level', 'excess_threshold',
           'explicit_step', 'inject', 'multigrid_cg', 'new_positions', 'newton_residual',
           'points_by_id_f32', 'prescribe', 'prolong', 'self_contact', 'settle',
           'spring_forces', 'start_velocity', 'strain_limit', 'strain_stats', 'system_apply',
           'system_diagonal', 'tangent_strain_limit')
# Every kernel by name: SERIAL holds the serial builds, PARALLEL the parallel builds of
# those that have one (jit.serial_and_parallel) and the serial build of the others.
SERIAL = SimpleNamespace(**{name: globals()[name] for name in KERNELS})
PARALLEL = SimpleNamespace(**{name: globals().get(name + '_parallel', globals()[name])
                              for name in KERNELS})


def builds(rows, cols, threads):
    """
    Return the kernel set for a level of ``rows x cols`` points and ``threads`` threads.

    The parallel builds only where they split the level among threads: with more than one
    thread, on levels ``chunk_count`` splits (those of ``PAR_MIN_POINTS`` points or more).
    """
    return PARALLEL if threads > 1 and rows * cols >= PAR_MIN_POINTS else SERIAL


__all__ = ['anchor', 'assemble_hierarchy', 'body_contact', 'builds', 'chunk_count',
           'conjugate_gradient', 'conjugate_gradient_parallel', 'contact', 'DRIVEN', 'energy',
           'eq6_first_sweep', 'eq6_second_sweep', 'eq7_level', 'eq7_level_parallel',
           'excess_threshold', 'explicit_step', 'FREE', 'inject', 'KERNELS', 'multigrid_cg',
           'new_positions', 'newton_residual', 'PAR_MIN_POINTS', 'PARALLEL', 'PINNED',
           'points_by_id_f32', 'prescribe', 'prolong', 'SERIAL', 'self_contact', 'settle',
           'spring_forces',
           'start_velocity', 'STENCIL_DC', 'STENCIL_DR', 'STENCIL_SIZE', 'strain_limit',
           'strain_limit_parallel', 'strain_stats', 'strain_stats_parallel', 'system_apply',
           'system_apply_parallel', 'system_diagonal', 'tangent_strain_limit']
