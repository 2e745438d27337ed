"""
launch/sim.launch.py and rviz/hcloth.rviz: what they name exists and matches the node.

``launch`` and ``launch_ros`` are not installable from PyPI, so the launch file is run
against stand-ins of them that record what it makes; where the real packages are installed
(a ROS 2 install) the real ones are used instead.
"""

import ast
import importlib.util
import os
import sys
import types

from hcloth_ros.node_params import NODE_PARAMS
import pytest
from rclpy import qos
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH_FILE = os.path.join(REPO, 'launch', 'sim.launch.py')
RVIZ_FILE = os.path.join(REPO, 'rviz', 'hcloth.rviz')

# the launch arguments and their defaults, with the share directory resolved to REPO
DEFAULTS = {
    'params_file': os.path.join(REPO, 'config', 'hanging.yaml'),
    'namespace': '',
    'use_sim_time': 'false',
    'rerun_path': '',
    'bag_path': '',
    'rviz': 'false',
}
# values given on the command line that YAML would read as other types than the parameters'
GIVEN = {
    'params_file': os.path.join(REPO, 'config', 'fold.yaml'),
    'namespace': 'robot1',
    'use_sim_time': 'True',
    'rerun_path': 'true',
    'bag_path': '2024',
    'rviz': 'true',
}
# the node's parameters GIVEN sets through the launch file, as the node must receive them
TYPED = {'use_sim_time': True, 'rerun_path': 'true', 'bag_path': '2024'}
# executables of other packages the launch file may start: (package, executable)
EXTERNAL = {('rviz2', 'rviz2')}

# what RViz shows: topic -> (display class, reliability, durability), as the node publishes
DISPLAYS = {
    '/cloth/points': ('rviz_default_plugins/PointCloud2', 'Best Effort', 'Volatile'),
    '/cloth/lod_marker': ('rviz_default_plugins/Marker', 'Reliable', 'Volatile'),
    '/cloth/scene': ('rviz_default_plugins/MarkerArray', 'Reliable', 'Transient Local'),
}
# the message type a display of each class shows
DISPLAY_OF_TYPE = {'PointCloud2': 'rviz_default_plugins/PointCloud2',
                   'Marker': 'rviz_default_plugins/Marker',
                   'MarkerArray': 'rviz_default_plugins/MarkerArray'}
# RViz's names of the QoS policies (two maps: the enums share their integer values)
RVIZ_RELIABILITY = {qos.ReliabilityPolicy.BEST_EFFORT: 'Best Effort',
                    qos.ReliabilityPolicy.RELIABLE: 'Reliable'}
RVIZ_DURABILITY = {qos.DurabilityPolicy.VOLATILE: 'Volatile',
                   qos.DurabilityPolicy.TRANSIENT_LOCAL: 'Transient Local'}


def console_scripts():
    """Return the console_scripts names of setup.py, read from its source (not run)."""
    with open(os.path.join(REPO, 'setup.py')) as f:
        tree = ast.parse(f.read())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            scripts = ast.literal_eval(node.value)['console_scripts']
            return {entry.split('=')[0].strip() for entry in scripts}
    raise AssertionError('setup.py has no entry_points')


def load_launch_file():
    """Execute the launch file as ``ros2 launch`` does; return it as a module."""
    spec = importlib.util.spec_from_file_location('sim_launch', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def real_launch_installed():
    """
    Tell whether the real launch and launch_ros are importable.

    A plain ``import launch`` is not enough: from the repository root the launch/ folder
    itself imports as an empty namespace package.
    """
    try:
        from launch import LaunchDescription  # noqa: F401
        from launch_ros.actions import Node  # noqa: F401
    except ImportError:
        return False
    return True


def check_executables(nodes):
    """Assert the launch starts sim_node and rviz2 only, each an executable that exists."""
    assert set(nodes) == {('hcloth_ros', 'sim_node'), ('rviz2', 'rviz2')}
    for package, executable in nodes:
        if package == 'hcloth_ros':
            assert executable in console_scripts()
        else:
            assert (package, executable) in EXTERNAL


def test_launch_file_compiles():
    with open(LAUNCH_FILE) as f:
        code = compile(f.read(), LAUNCH_FILE, 'exec')
    assert 'generate_launch_description' in code.co_names


# --- stand-ins of launch and launch_ros -------------------------------------------------
STAND_INS = {
    'launch': ['LaunchDescription', 'LaunchContext'],
    'launch.actions': ['DeclareLaunchArgument', 'ExecuteProcess', 'GroupAction',
                       'IncludeLaunchDescription', 'SetEnvironmentVariable'],
    'launch.conditions': ['IfCondition', 'UnlessCondition'],
    'launch.substitutions': ['EnvironmentVariable', 'LaunchConfiguration',
                             'PathJoinSubstitution', 'PythonExpression', 'TextSubstitution'],
    'launch_ros': [],
    'launch_ros.actions': ['Node', 'PushRosNamespace', 'SetParameter'],
    'launch_ros.parameter_descriptions': ['Parameter', 'ParameterFile', 'ParameterValue'],
    'launch_ros.substitutions': ['FindPackageShare', 'FindPackagePrefix'],
}


class Made:
    """One object the launch file made of a stand-in class: the class and its arguments."""

    def __init__(self, kind, args, kwargs):
        self.kind, self.args, self.kwargs = kind, args, kwargs

    def __repr__(self):
        return f'{self.kind}(*{self.args!r}, **{self.kwargs!r})'


def install_stand_ins(monkeypatch):
    """Put recording stand-ins of launch and launch_ros in sys.modules; return the record."""
    made = []

    def stand_in(kind):
        def make(*args, **kwargs):
            made.append(Made(kind, args, kwargs))
            return made[-1]
        return make

    for name, kinds in STAND_INS.items():
        module = types.ModuleType(name)
        module.__path__ = []      # a package, so that its submodules import
        for kind in kinds:
            setattr(module, kind, stand_in(kind))
        monkeypatch.setitem(sys.modules, name, module)
    return made


def resolve(value, arguments):
    """Return the text a stand-in substitution (or a list of them) gives with ``arguments``."""
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple)):
        return ''.join(resolve(v, arguments) for v in value)
    assert isinstance(value, Made), value
    if value.kind == 'LaunchConfiguration':
        assert value.args[0] in arguments, f'{value.args[0]} is not a launch argument'
        return arguments[value.args[0]]
    if value.kind == 'FindPackageShare':
        assert value.args == ('hcloth_ros',), value
        # share/hcloth_ros is laid out like the source tree (setup.py's data_files)
        return REPO
    if value.kind == 'PathJoinSubstitution':
        return os.path.join(*(resolve(part, arguments) for part in value.args[0]))
    raise AssertionError(f'substitution the test does not know: {value!r}')


def test_launch_description_with_stand_ins(monkeypatch):
    if real_launch_installed():
        pytest.skip('the real launch is installed: test_launch_description_with_real_launch')
    made = install_stand_ins(monkeypatch)
    description = load_launch_file().generate_launch_description()
    assert description.kind == 'LaunchDescription'
    entities = description.args[0]
    actions = [m for m in made if m.kind in ('DeclareLaunchArgument', 'Node',
                                             'ExecuteProcess', 'IncludeLaunchDescription',
                                             'GroupAction')]
    assert [m for m in actions if m not in entities] == [], 'actions made but not launched'
    assert sorted(e.kind for e in entities) == ['DeclareLaunchArgument'] * 6 + ['Node'] * 2

    declared = [e for e in entities if e.kind == 'DeclareLaunchArgument']
    defaults = {d.args[0]: resolve(d.kwargs['default_value'], {}) for d in declared}
    assert defaults == DEFAULTS
    assert os.path.isfile(defaults['params_file'])
    for d in declared:
        assert isinstance(d.kwargs['description'], str) and len(d.kwargs['description']) > 10

    nodes = {(n.kwargs['package'], n.kwargs['executable']): n
             for n in entities if n.kind == 'Node'}
    check_executables(nodes)

    sim = nodes['hcloth_ros', 'sim_node']
    assert sim.kwargs['name'] == 'hcloth_sim'
    assert sim.kwargs['output'] == 'screen'
    assert 'condition' not in sim.kwargs
    assert resolve(sim.kwargs['namespace'], GIVEN) == 'robot1'
    params_file, overrides = sim.kwargs['parameters']
    # the file first: the typed values after it override whatever it sets
    assert resolve(params_file, GIVEN) == GIVEN['params_file']
    assert resolve(params_file, DEFAULTS) == DEFAULTS['params_file']
    assert set(overrides) == set(TYPED)
    for name, value in overrides.items():
        assert value.kind == 'ParameterValue'
        assert value.kwargs['value_type'] is type(TYPED[name])
        assert resolve(value.args[0], GIVEN) == GIVEN[name]

    rviz = nodes['rviz2', 'rviz2']
    flag, config = rviz.kwargs['arguments']
    assert flag == '-d'
    assert resolve(config, GIVEN) == RVIZ_FILE and os.path.isfile(RVIZ_FILE)
    condition = rviz.kwargs['condition']
    assert condition.kind == 'IfCondition'
    assert resolve(condition.args[0], DEFAULTS) == 'false'
    assert resolve(condition.args[0], GIVEN) == 'true'
    # the node's stamps are simulated time whatever its use_sim_time: RViz follows /clock
    assert rviz.kwargs['parameters'] == [{'use_sim_time': True}]


def test_launch_description_with_real_launch(monkeypatch, tmp_path):
    if not real_launch_installed():
        pytest.skip('launch and launch_ros are not installed (no PyPI packages)')
    from launch import LaunchContext, LaunchDescription
    from launch.actions import DeclareLaunchArgument
    from launch.utilities import normalize_to_list_of_substitutions, perform_substitutions
    import launch_ros.actions
    from launch_ros.utilities import evaluate_parameters, normalize_parameters

    # an ament prefix whose share/hcloth_ros is this source tree, for FindPackageShare
    marker = tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages'
    marker.mkdir(parents=True)
    (marker / 'hcloth_ros').touch()
    os.symlink(REPO, tmp_path / 'share' / 'hcloth_ros')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    share = os.path.join(str(tmp_path), 'share', 'hcloth_ros')

    # record the arguments of each Node the launch file makes
    made = []

    class RecordedNode(launch_ros.actions.Node):
        """The real Node, recording the arguments it is made with."""

        def __init__(self, **kwargs):
            made.append(kwargs)
            super().__init__(**kwargs)

    monkeypatch.setattr(launch_ros.actions, 'Node', RecordedNode)
    description = load_launch_file().generate_launch_description()
    assert isinstance(description, LaunchDescription)
    assert sorted(type(e).__name__ for e in description.entities) == (
        ['DeclareLaunchArgument'] * 6 + ['RecordedNode'] * 2)

    def text(context, value):
        return perform_substitutions(context, normalize_to_list_of_substitutions(value))

    context = LaunchContext()
    declared = description.get_launch_arguments()
    assert all(isinstance(d, DeclareLaunchArgument) for d in declared)
    defaults = {d.name: perform_substitutions(context, d.default_value) for d in declared}
    assert defaults == dict(DEFAULTS, params_file=os.path.join(share, 'config', 'hanging.yaml'))
    assert os.path.isfile(defaults['params_file'])
    assert all(len(d.description) > 10 for d in declared)

    nodes = {(k['package'], k['executable']): k for k in made}
    check_executables(nodes)

    context.launch_configurations.update(GIVEN)
    sim = nodes['hcloth_ros', 'sim_node']
    assert sim['name'] == 'hcloth_sim' and sim['output'] == 'screen'
    assert sim.get('condition') is None
    assert text(context, sim['namespace']) == 'robot1'
    # what launch_ros writes into the node's parameter files: the types count
    params_file, overrides = evaluate_parameters(context, normalize_parameters(
        sim['parameters']))
    assert str(params_file) == GIVEN['params_file']
    assert overrides == TYPED
    assert {n: type(v) for n, v in overrides.items()} == {n: type(v) for n, v in TYPED.items()}

    rviz = nodes['rviz2', 'rviz2']
    assert [text(context, a) for a in rviz['arguments']] == [
        '-d', os.path.join(share, 'rviz', 'hcloth.rviz')]
    assert os.path.isfile(os.path.join(share, 'rviz', 'hcloth.rviz'))
    assert rviz['condition'].evaluate(context) is True
    context.launch_configurations['rviz'] = 'false'
    assert rviz['condition'].evaluate(context) is False
    context.launch_configurations['use_sim_time'] = 'false'
    (rviz_params,) = evaluate_parameters(context, normalize_parameters(rviz['parameters']))
    assert rviz_params == {'use_sim_time': True}


# --- the RViz configuration ---------------------------------------------------------------
def rviz_config():
    """Return rviz/hcloth.rviz parsed."""
    with open(RVIZ_FILE) as f:
        return yaml.safe_load(f)


def node_publishers():
    """
    Return the node's publishers of displayed types: topic -> (display, QoS names).

    Read from hcloth_ros/node.py's ``create_publisher`` calls; the QoS argument is
    evaluated with rclpy (a depth alone is rclpy's default profile of that depth).
    """
    path = os.path.join(REPO, 'hcloth_ros', 'node.py')
    with open(path) as f:
        source = f.read()
    found = {}
    for call in ast.walk(ast.parse(source)):
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                and call.func.attr == 'create_publisher'):
            continue
        msg_type, topic, qos_arg = call.args[:3]
        if not (isinstance(msg_type, ast.Name) and msg_type.id in DISPLAY_OF_TYPE):
            continue
        profile = eval(ast.get_source_segment(source, qos_arg), vars(qos))
        if isinstance(profile, int):
            profile = qos.QoSProfile(depth=profile)
        found['/' + ast.literal_eval(topic)] = (
            DISPLAY_OF_TYPE[msg_type.id], RVIZ_RELIABILITY[profile.reliability],
            RVIZ_DURABILITY[profile.durability])
    return found


def test_rviz_displays_follow_the_node():
    config = rviz_config()
    manager = config['Visualization Manager']
    frame_id = next(p.default for p in NODE_PARAMS if p.name == 'frame_id')
    assert frame_id == 'world'
    assert manager['Global Options']['Fixed Frame'] == frame_id
    displays = manager['Displays']
    assert [d['Class'] for d in displays if 'Topic' not in d] == ['rviz_default_plugins/Grid']
    shown = {d['Topic']['Value']: (d['Class'], d['Topic']['Reliability Policy'],
                                   d['Topic']['Durability Policy'])
             for d in displays if 'Topic' in d}
    assert len(shown) == len(displays) - 1, 'two displays of one topic'
    assert shown == DISPLAYS
    # the same topics and QoS as the node's publishers: a mismatched reliability or
    # durability would leave a display empty (best effort cloud, reliable subscription)
    assert node_publishers() == DISPLAYS
    assert all(d['Enabled'] is True for d in displays)


def test_rviz_view_and_points():
    manager = rviz_config()['Visualization Manager']
    cloud = next(d for d in manager['Displays']
                 if 'Topic' in d and d['Topic']['Value'] == '/cloth/points')
    assert cloud['Style'] == 'Flat Squares'
    assert cloud['Size (m)'] == pytest.approx(0.01)
    assert cloud['Position Transformer'] == 'XYZ'
    view = manager['Views']['Current']
    assert view['Class'] == 'rviz_default_plugins/Orbit'
    assert view['Target Frame'] == '<Fixed Frame>'
    focal = view['Focal Point']
    # inside the default scene's cloth: x -0.5..0.5, y 0..1, z 0.5..1.5 m
    assert -0.5 <= focal['X'] <= 0.5 and 0 <= focal['Y'] <= 1 and 0.5 <= focal['Z'] <= 1.5
    assert 1.5 <= view['Distance'] <= 5
    assert 0 < view['Pitch'] < 1.2     # from above, not from below nor straight down


def test_typed_parameters_are_the_nodes():
    defaults = {p.name: p.default for p in NODE_PARAMS}
    assert 'use_sim_time' not in defaults     # rclpy declares it on every node
    # the launch file's values must have the types the node declared, or rclpy refuses them
    assert {n: type(defaults[n]) for n in TYPED if n != 'use_sim_time'} == {
        'rerun_path': str, 'bag_path': str}
