"""Scene parameter files: every shipped config builds, bad values are refused."""

import glob
import os

from conftest import load_tool
from hcloth_ros import params
from hcloth_ros.core import make_solver
import numpy as np
import pytest

CONFIG = os.path.join(os.path.dirname(os.path.dirname(__file__)), 'config')


@pytest.mark.parametrize('path', sorted(glob.glob(os.path.join(CONFIG, '*.yaml'))))
def test_shipped_configs_build(path):
    values = params.resolve(params.load_file(path))
    model, solver, state, control = params.build_all(values)
    # the finest level has 2^(L-1) (n0 - 1) + 1 points a side, as documented
    n0u, n0v = values['cloth.resolution']
    lv = model.level(model.level_count - 1)
    assert (lv.cols, lv.rows) == (2 ** (model.level_count - 1) * (n0u - 1) + 1,
                                  2 ** (model.level_count - 1) * (n0v - 1) + 1)
    assert model.total_mass == pytest.approx(values['cloth.mass'])
    assert solver.name == values['solver.name']
    report = solver.step(state, control, values['solver.dt'])
    assert report.ok and np.all(np.isfinite(state.q[-1]))


def test_hanging_pins_two_level0_corners():
    values = params.resolve(params.load_file(os.path.join(CONFIG, 'hanging.yaml')))
    model, _, state, control = params.build_all(values)
    ends = state.points_by_id(model, 0)[control.pins]
    assert np.allclose(ends, [[-0.5, 0.0, 1.5], [0.5, 0.0, 1.5]])


@pytest.mark.parametrize('name,value', [('cloth.width', -1.0), ('cloth.levels', 11),
                                        ('scene.friction', float('nan')),
                                        ('cloth.contraction', [0.5, 1.5])])
def test_out_of_range_values_are_refused(name, value):
    with pytest.raises(ValueError, match=name.replace('.', r'\.')):
        params.resolve({name: value})


def test_pin_sentinel_and_bad_ids():
    assert params.pin_ids([-1]) == []
    values = params.resolve({'pinned_points': [10 ** 6]})
    with pytest.raises(IndexError, match='out of range'):
        params.build_all(values)


def test_defaults_are_the_hanging_scene():
    # `ros2 run hcloth_ros sim_node` with no parameter file runs config/hanging.yaml
    defaults = params.resolve({})
    hanging = params.resolve(params.load_file(os.path.join(CONFIG, 'hanging.yaml')))
    for name, value in hanging.items():
        assert np.all(np.asarray(defaults[name]) == np.asarray(value)), name


def test_readme_parameter_table_is_the_specs():
    # the table tools/param_table.py prints, row for row: names, types, defaults, what is
    # allowed, runtime or not, meaning
    tool = load_tool('param_table')
    readme = open(os.path.join(os.path.dirname(CONFIG), 'README.md')).read()
    assert tool.table() in readme


def test_self_contact_parameters_reach_the_solver():
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2})
    assert params.build_solver(params.build_model(values), values).self_contact is None
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'self_contact.thickness': 0.004, 'self_contact.friction': 0.2,
                             'self_contact.iterations': 3, 'self_contact.interval': 2})
    contact = params.build_solver(params.build_model(values), values).self_contact
    assert (contact.thickness, contact.friction, contact.iterations, contact.interval) == \
        (0.004, 0.2, 3, 2)


def test_contact_strain_parameters_reach_the_solver():
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2})
    solver = params.build_solver(params.build_model(values), values)
    assert (solver.contact_strain, solver.contact_sweeps, solver.contact_relaxation) == \
        ('tangent', 300, 1.5)
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'solver.contact_relaxation': 1.0})
    assert params.build_solver(params.build_model(values), values).contact_relaxation == 1.0
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'solver.contact_strain': 'jacobi'})
    solver = params.build_solver(params.build_model(values), values)
    assert (solver.contact_strain, solver.contact_sweeps) == ('jacobi', 10)
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'solver.contact_strain': 'jacobi', 'solver.contact_sweeps': 100})
    solver = params.build_solver(params.build_model(values), values)
    assert (solver.contact_strain, solver.contact_sweeps) == ('jacobi', 100)
    for name, value in (('solver.contact_strain', 'gauss'), ('solver.contact_sweeps', -1),
                        ('solver.contact_relaxation', 2.0)):
        with pytest.raises(ValueError, match=name.replace('.', r'\.')):
            params.resolve({name: value})


def test_newton_tolerance_steps_parameter_reaches_the_solver():
    # the node's default is moved (a steady tick), the solver class's all
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2})
    assert params.build_solver(params.build_model(values), values).newton_tolerance_steps \
        == 'moved'
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'solver.newton_tolerance_steps': 'all'})
    assert params.build_solver(params.build_model(values), values).newton_tolerance_steps \
        == 'all'
    assert make_solver('multigrid', params.build_model(values)).newton_tolerance_steps == 'all'
    with pytest.raises(ValueError, match=r'solver\.newton_tolerance_steps'):
        params.resolve({'solver.newton_tolerance_steps': 'some'})


def test_retry_strain_parameter_reaches_the_solver_and_old_recordings_go_without_it():
    # the node's default 0.5, the solver class's None (off); 0: off
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2})
    model = params.build_model(values)
    assert params.build_solver(model, values).retry_strain == 0.5
    assert make_solver('multigrid', model).retry_strain is None
    assert params.build_solver(model, dict(values, **{'solver.retry_strain': 0.0})) \
        .retry_strain is None
    # a recording started before the parameter existed replays as it ran: without retries
    older = {name: value for name, value in values.items() if name != 'solver.retry_strain'}
    assert params.build_solver(model, older).retry_strain is None
    with pytest.raises(ValueError, match='retry_strain'):
        make_solver('multigrid', model, retry_strain=10.0)


def test_edges_and_solved_strain_limit_reach_the_solver_and_old_recordings_go_without():
    """``self_contact.edges`` (auto) and ``solver.solved_strain_limit`` (0: off)."""
    values = params.resolve({'cloth.resolution': [5, 5], 'cloth.levels': 2,
                             'self_contact.thickness': 0.004})
    model = params.build_model(values)
    solver = params.build_solver(model, values)
    assert solver.self_contact.edges == 'auto' and solver.solved_strain_limit is None
    solver = params.build_solver(model, dict(values, **{'self_contact.edges': 'all',
                                                        'solver.solved_strain_limit': 0.1}))
    assert solver.self_contact.edges == 'all' and solver.solved_strain_limit == 0.1
    # a recording started before them replays as it ran: the sharp creases only (the
    # creases of then), no solved limit
    older = {name: value for name, value in values.items()
             if name not in ('self_contact.edges', 'solver.solved_strain_limit')}
    solver = params.build_solver(model, older)
    assert solver.self_contact.edges == 'sharp' and solver.solved_strain_limit is None
    with pytest.raises(ValueError, match='self_contact.edges'):
        params.resolve({'self_contact.edges': 'some'})


def test_command_line_assignments_are_yaml_values():
    assert params.assignments(['solver.dt=0.01', 'cloth.levels=5', 'a=null', 'b=[1, 2]',
                               'c=x=y']) == {'solver.dt': 0.01, 'cloth.levels': 5,
                                             'a': None, 'b': [1, 2], 'c': 'x=y'}
    for bad in ('solver.dt', '=1'):
        with pytest.raises(ValueError, match='expected NAME=VALUE'):
            params.assignments([bad])
    # the tools' -p: engine parameters only (resolve leaves other names out)
    assert params.overrides(['solver.dt=0.01']) == {'solver.dt': 0.01}
    assert 'solver.extra_cg_iterations' not in params.resolve({'solver.extra_cg_iterations': 2})
    with pytest.raises(ValueError, match='unknown parameters: solver.extra_cg_iterations'):
        params.overrides(['solver.extra_cg_iterations=2'])
