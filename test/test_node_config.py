"""
The node's configuration checks and interface messages without a ROS graph.

What a start-up or a runtime change is refused for (one line naming the parameter, the
value and what is allowed), params files keyed to other nodes, sim-time stamps and the
``/diagnostics`` status.
"""

from diagnostic_msgs.msg import DiagnosticStatus
from hcloth_ros import params
from hcloth_ros.diagnostics import node_status
from hcloth_ros.lifetime import rcl_reason, unreadable_params_files
from hcloth_ros.node_params import (as_declared_type, check_change, mixed_lists,
                                    overrides_in, params_files, sections_for, SPEC_BY_NAME,
                                    startup_problems)
from hcloth_ros.ros_msgs import sim_stamp
from hcloth_ros.tick_stats import TickStats
import pytest


@pytest.mark.parametrize('name, value, words', [
    ('cloth.width', 0.0, 'out of range; allowed: a number in 0.01 .. 100'),
    ('cloth.width', float('nan'), 'out of range'),
    ('cloth.width', 'wide', 'wrong type'),
    ('cloth.levels', 2.5, 'wrong type; allowed: an integer in 1 .. 10'),
    ('cloth.resolution', [9, 9, 9], '3 values; allowed: a list of integers, each in 2 .. '
                                    '1025, exactly 2'),
    ('cloth.origin', [0.0, 1e5, 0.0], 'out of range'),
    ('scene.boxes', [0.0] * 7, '7 values'),
    ('scene.spheres', [0.0, 0.0, 0.5, 0.1, 0.2], '5 values'),
    ('solver.name', 'multigird', 'unknown value; allowed: one of multigrid, hierarchical'),
    ('solver.integrator', 'rk4', 'one of bdf2, backward_euler'),
    ('scene.ground', 1, 'wrong type; allowed: true or false'),
    ('grippers', [1, 2], 'wrong type; allowed: a list of strings'),
    ('real_time_factor', -1.0, 'out of range'),
])
def test_a_disallowed_value_is_named_with_what_is_allowed(name, value, words):
    reason = params.check_value(SPEC_BY_NAME[name], value)
    assert reason.startswith(f'{name} = {value!r}: ') and words in reason


@pytest.mark.parametrize('name, value', [
    ('cloth.width', 1), ('cloth.width', 2.5), ('scene.boxes', [0.0]),
    ('scene.boxes', [0, 0, 0.5, 0.1, 0.1, 0.1]), ('pinned_points', [-1]),
    ('cloth.stiffness_scale', [1, 2, 4]), ('scene.ground', False),
    ('real_time_factor', 0.0), ('solver.name', 'hierarchical'),
])
def test_allowed_values_pass(name, value):
    assert params.check_value(SPEC_BY_NAME[name], value) is None


def test_integers_become_floats_only_where_a_float_is_declared():
    spec = SPEC_BY_NAME
    assert as_declared_type(spec['cloth.width'], 1) == 1.0
    assert type(as_declared_type(spec['cloth.width'], 1)) is float
    boxes = as_declared_type(spec['scene.boxes'], [0, 0, 1, 1, 1, 1])
    assert boxes == [0.0, 0.0, 1.0, 1.0, 1.0, 1.0] and type(boxes[0]) is float
    assert type(as_declared_type(spec['cloth.levels'], 3)) is int
    assert as_declared_type(spec['scene.ground'], True) is True
    assert as_declared_type(spec['cloth.width'], 'x') == 'x'     # left for the check


def test_start_up_problems_are_one_line_each_and_ignore_other_names():
    problems = startup_problems({'cloth.width': -1.0, 'solver.name': 'x', 'use_sim_time': 3,
                                 'cloth.height': 0.5})
    assert len(problems) == 2 and all('\n' not in p for p in problems)
    assert problems[0].startswith('cloth.width') and problems[1].startswith('solver.name')


def test_runtime_changes_get_the_same_checks(tmp_path):
    model = params.build_model(params.resolve())
    assert 'out of range' in check_change('scene.ground_z', 1e9, model)
    assert '5 values' in check_change('scene.boxes', [0.0, 0.0, 0.5, 0.1, 0.1], model)
    assert check_change('scene.ground_z', 0.1, model) is None
    assert 'out of range 0..3' in check_change('lod_level', 5, model)


def test_params_files_are_found_in_ros_arguments_only():
    argv = ['sim_node', '--params-file', 'not_ros.yaml', '--ros-args', '--params-file',
            'a.yaml', '-p', 'x:=1', '--', '--ros-args', '--params-file', 'b.yaml']
    assert params_files(argv) == ['a.yaml', 'b.yaml']


@pytest.mark.parametrize('key, fqn, matches', [
    ('/**', '/hcloth_sim', True), ('/**', '/robot/hcloth_sim', True),
    ('hcloth_sim', '/hcloth_sim', True), ('/hcloth_sim', '/robot/hcloth_sim', False),
    ('/robot/hcloth_sim', '/robot/hcloth_sim', True), ('/*/hcloth_sim', '/robot/hcloth_sim',
                                                       True),
    ('/**/hcloth_sim', '/hcloth_sim', True), ('/**/hcloth_sim', '/a/b/hcloth_sim', True),
    ('other_node', '/hcloth_sim', False), ('/hcloth_*', '/hcloth_sim', True),
])
def test_a_params_file_section_applies_to_the_node_it_names(tmp_path, key, fqn, matches):
    path = tmp_path / 'p.yaml'
    path.write_text(f'{key}:\n  ros__parameters:\n    cloth:\n      width: 2.0\n')
    assert sections_for(str(path), fqn) == ([key] if matches else [])


def test_unreadable_params_files_are_one_line_each(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('a: [\n')
    good = tmp_path / 'good.yaml'
    good.write_text('/**:\n  ros__parameters: {}\n')
    lines = unreadable_params_files(['x', '--ros-args', '--params-file', str(bad),
                                     '--params-file', str(good), '--params-file',
                                     str(tmp_path / 'missing.yaml')])
    assert len(lines) == 2 and all('\n' not in line for line in lines)
    assert str(bad) in lines[0] and 'No such file' in lines[1]


def test_rcl_reason_drops_source_locations():
    text = ("failed to initialize rcl: Couldn't parse params file: 'x'. Error: Error opening "
            'YAML file, at /project/src/parser.c:271, at /project/src/rcl/arguments.c:415')
    assert rcl_reason(text) == ("failed to initialize rcl: Couldn't parse params file: 'x'. "
                                'Error: Error opening YAML file')


@pytest.mark.parametrize('seconds, sec, nanosec', [
    (0.0, 0, 0), (60 * (1 / 60), 1, 0), (1.5, 1, 500_000_000), (1 / 60, 0, 16_666_667)])
def test_sim_stamps_round_to_the_nanosecond(seconds, sec, nanosec):
    stamp = sim_stamp(seconds)
    assert (stamp.sec, stamp.nanosec) == (sec, nanosec)


def _status(**changes):
    args = {'name': '/hcloth_sim', 'stamp': sim_stamp(2.0), 'recent': {},
            'real_time_factor': 1.0, 'target_factor': 1.0, 'paused': False, 'levels': 4,
            'level_count': 4, 'governor_cap': 3, 'refused': None, 'sim_time': 2.0}
    args.update(changes)
    return node_status(**args).status[0]


def test_diagnostics_level_says_what_is_wrong():
    assert _status().level == DiagnosticStatus.OK
    slow = _status(real_time_factor=0.5)
    assert slow.level == DiagnosticStatus.WARN and '0.50 of 1' in slow.message
    assert _status(real_time_factor=0.5, paused=True).level == DiagnosticStatus.OK
    shed = _status(governor_cap=2)
    assert shed.level == DiagnosticStatus.WARN and 'level 2' in shed.message
    assert _status(governor_cap=None, real_time_factor=0.1,
                   target_factor=0.0).level == DiagnosticStatus.OK
    refused = _status(refused='blow-up')
    assert refused.level == DiagnosticStatus.ERROR and 'blow-up' in refused.message


def test_diagnostics_carry_the_recent_tick_statistics():
    stats = TickStats()
    for i in range(100):
        t = (i + 1) * 1e-4          # the last 10 ticks: 9.1 .. 10 ms
        stats.add(step=t, pack=0.0, publish=0.0, send=0.0, record=0.0, tick=t, levels=4,
                  sim_time=i / 60)
    recent = stats.recent(10)
    assert recent['tick']['p50'] == pytest.approx(9.55, abs=1e-9)
    assert stats.recent(0) == {}
    values = {kv.key: kv.value for kv in _status(recent=recent).values}
    assert values['tick_p50_ms'] == '9.550' and values['step_p99_ms'] == '9.991'
    assert values['governor_cap'] == '3' and values['real_time_factor_target'] == '1'


def test_lists_mixing_integers_and_decimals_are_named():
    doc = {'/**': {'ros__parameters': {'scene': {'boxes': [0, 0, 0.5, 0.1, 0.1, 0.1],
                                                 'spheres': [0.0, 0.0, 0.5, 0.1]},
                                       'pinned_points': [0, 8]}}}
    lines = mixed_lists(doc)
    assert len(lines) == 1 and lines[0].startswith('scene.boxes = [0, 0, 0.5')
    assert lines[0].endswith('[0.0, 0.0, 0.5, 0.1, 0.1, 0.1]')
    argv = ['sim_node', '--ros-args', '-p', 'scene.spheres:=[0,0,1.5,0.2]', '-p',
            'cloth.width:=2']
    assert overrides_in(argv) == {'scene.spheres': [0, 0, 1.5, 0.2], 'cloth.width': 2}
    assert len(mixed_lists(overrides_in(argv))) == 1


def test_no_factor_in_a_window_a_reset_sent_back():
    status = _status(real_time_factor=None)
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == DiagnosticStatus.OK and values['real_time_factor'] == 'n/a'
