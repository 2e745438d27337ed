"""MCAP bags: what BagWriter writes reads back, decoded through its own schemas, unchanged."""

import warnings

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from hcloth_ros import bag
from hcloth_ros.bag import BagWriter
from hcloth_ros.ros_msgs import pointcloud2
from mcap.reader import make_reader
from mcap.records import Chunk, DataEnd, Footer, Statistics
from mcap.stream_reader import StreamReader
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray
import yaml

POINTS_HASH = 'RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5'


def _read_decoded(path):
    """Return every message of the bag, decoded by mcap_ros2 from the schemas in the file."""
    with warnings.catch_warnings():
        # the module warns on import that a newer entry point exists; this one is the brief's
        warnings.simplefilter('ignore', DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages
    return list(read_ros2_messages(path))


def _cloud(n, seed, stamp):
    """Return a PointCloud2 of ``n`` random points (m) and the points it holds."""
    points = np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 3)).astype(np.float32)
    return pointcloud2(points, f'cloth_{seed}', stamp), points


def _marker(marker_id, frame_id, points):
    """Return a LINE_STRIP marker through ``points`` (m)."""
    marker = Marker(ns='test', id=marker_id, type=Marker.LINE_STRIP, action=Marker.ADD,
                    lifetime=Duration(sec=2, nanosec=500))
    marker.header.frame_id = frame_id
    marker.scale.x = 0.01
    marker.color = ColorRGBA(r=0.25, g=0.5, b=0.75, a=1.0)
    marker.points = [Point(x=x, y=y, z=z) for x, y, z in points]
    return marker


def _diagnostics(stamp):
    """Return a DiagnosticArray with one status of two key/values."""
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name='cloth_sim: step',
                              message='over budget', hardware_id='sim',
                              values=[KeyValue(key='step_ms', value='17.5'),
                                      KeyValue(key='levels', value='3')])
    array = DiagnosticArray(status=[status])
    array.header.stamp = stamp
    return array


def _written(path):
    """Write one bag with every supported type; return {topic: [(stamp_ns, msg), ...]}."""
    big, _ = _cloud(500, 1, Time(sec=1, nanosec=5))
    small, _ = _cloud(7, 2, Time(sec=1, nanosec=6))
    line = _marker(3, 'world', [(0.0, 0.0, 0.0), (1.0, 2.0, 3.0), (-0.5, 0.25, 4.0)])
    other = _marker(4, 'cloth', [(9.0, 8.0, 7.0)])
    expected = {
        '/cloth/points': [(1_000_000_005, big), (1_016_666_672, small)],
        '/cloth/lod_marker': [(1_000_000_005, line)],
        '/scene/markers': [(2_000_000_000, MarkerArray(markers=[line, other]))],
        '/clock': [(0, Clock(clock=Time(sec=0, nanosec=0))),
                   (3_000_000_007, Clock(clock=Time(sec=3, nanosec=7)))],
        '/diagnostics': [(2_500_000_000, _diagnostics(Time(sec=2, nanosec=500_000_000)))],
    }
    with BagWriter(path) as writer:
        writer.add_topic('/cloth/points', PointCloud2, qos='best_effort', depth=5)
        writer.add_topic('/cloth/lod_marker', Marker)
        writer.add_topic('/scene/markers', MarkerArray, transient_local=True, depth=1)
        writer.add_topic('/clock', Clock, qos='best_effort', depth=1)
        writer.add_topic('/diagnostics', DiagnosticArray)
        for topic, stamped in expected.items():
            for stamp, msg in stamped:
                writer.write(topic, msg, stamp)
    return expected


@pytest.fixture
def written_bag(tmp_path):
    """Return ``(path, expected)`` of a bag holding every supported type."""
    path = str(tmp_path / 'run.mcap')
    return path, _written(path)


def test_pointcloud2_depends_on_header_time_and_pointfield():
    assert bag.dependencies('sensor_msgs/msg/PointCloud2') == [
        'sensor_msgs/PointField', 'std_msgs/Header', 'builtin_interfaces/Time']
    text = bag.message_definition('sensor_msgs/msg/PointCloud2')
    lines = text.splitlines()
    assert [line for line in lines if line.startswith('MSG: ')] == [
        'MSG: sensor_msgs/PointField', 'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert lines.count('=' * 80) == 3
    assert lines[0].startswith('# This message holds a collection of N-dimensional points')
    assert 'std_msgs/Header header' in lines
    assert [line.split() for line in lines if 'point_step' in line][0][:2] == [
        'uint32', 'point_step']
    assert 'uint8 FLOAT32 = 7' in lines     # PointField's constants come along


def test_definitions_of_the_other_types_list_their_dependencies():
    assert bag.dependencies('rosgraph_msgs/msg/Clock') == ['builtin_interfaces/Time']
    assert bag.dependencies('diagnostic_msgs/msg/DiagnosticArray') == [
        'diagnostic_msgs/DiagnosticStatus', 'diagnostic_msgs/KeyValue', 'std_msgs/Header',
        'builtin_interfaces/Time']
    marker = bag.dependencies('visualization_msgs/msg/Marker')
    assert bag.dependencies('visualization_msgs/msg/MarkerArray') == (
        ['visualization_msgs/Marker'] + marker)
    assert {'geometry_msgs/Point', 'geometry_msgs/Pose', 'geometry_msgs/Quaternion',
            'std_msgs/ColorRGBA', 'builtin_interfaces/Duration'} <= set(marker)


@pytest.mark.parametrize('line, dependency', [
    ('std_msgs/Header header', 'std_msgs/Header'),
    ('Header header  # legacy spelling', 'std_msgs/Header'),
    ('PointField[] fields', 'pkg/PointField'),
    ('geometry_msgs/msg/Point[<=4] corners', 'geometry_msgs/Point'),
    ('geometry_msgs/Vector3[3] axes', 'geometry_msgs/Vector3'),
    ('uint8 FLOAT32 = 7', None),
    ('string<=10 name', None),
    ('string<=5[<=3] short_names', None),
    ('wstring title', None),
    ('float64[9] covariance', None),
    ('string FOO="a # b"', None),
    ('# Point[] commented_out', None),
    ('   ', None),
])
def test_field_dependency_reads_msg_lines(line, dependency):
    assert bag._field_dependency(line, 'pkg') == dependency


def test_messages_read_back_through_the_stored_schemas(written_bag):
    path, expected = written_bag
    got = {}
    for record in _read_decoded(path):
        got.setdefault(record.channel.topic, []).append(record)
    assert {t: len(r) for t, r in got.items()} == {t: len(m) for t, m in expected.items()}
    for topic, stamped in expected.items():
        assert [r.log_time_ns for r in got[topic]] == [s for s, _ in stamped]
        assert [r.publish_time_ns for r in got[topic]] == [s for s, _ in stamped]

    clouds = [r.ros_msg for r in got['/cloth/points']]
    for cloud, (_, sent) in zip(clouds, expected['/cloth/points']):
        assert bytes(cloud.data) == bytes(sent.data)
        assert (cloud.width, cloud.height, cloud.point_step) == (sent.width, 1, 12)
        assert cloud.header.frame_id == sent.header.frame_id
        assert [(f.name, f.offset, f.datatype) for f in cloud.fields] == [
            ('x', 0, 7), ('y', 4, 7), ('z', 8, 7)]
    assert [c.width for c in clouds] == [500, 7]
    assert clouds[0].header.stamp.nanosec == 5

    line = got['/cloth/lod_marker'][0].ros_msg
    assert [(p.x, p.y, p.z) for p in line.points] == [
        (0.0, 0.0, 0.0), (1.0, 2.0, 3.0), (-0.5, 0.25, 4.0)]
    assert (line.id, line.type, line.ns, line.header.frame_id) == (3, 4, 'test', 'world')
    assert (line.lifetime.sec, line.lifetime.nanosec, line.color.b) == (2, 500, 0.75)

    array = got['/scene/markers'][0].ros_msg
    assert [m.id for m in array.markers] == [3, 4]
    assert [(p.x, p.y, p.z) for p in array.markers[1].points] == [(9.0, 8.0, 7.0)]

    assert [(r.ros_msg.clock.sec, r.ros_msg.clock.nanosec) for r in got['/clock']] == [
        (0, 0), (3, 7)]

    status = got['/diagnostics'][0].ros_msg.status[0]
    # mcap_ros2 reads a byte as an int; rclpy holds it as a bytes of length 1
    assert (status.name, status.level, status.message) == ('cloth_sim: step', 1, 'over budget')
    assert [(v.key, v.value) for v in status.values] == [('step_ms', '17.5'), ('levels', '3')]


def test_raw_bytes_deserialise_to_the_written_messages(written_bag):
    path, expected = written_bag
    classes = {'/cloth/points': PointCloud2, '/cloth/lod_marker': Marker,
               '/scene/markers': MarkerArray, '/clock': Clock, '/diagnostics': DiagnosticArray}
    with open(path, 'rb') as f:
        got = {}
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            msg = deserialize_message(message.data, classes[channel.topic])
            got.setdefault(channel.topic, []).append(msg)
    assert got == {t: [m for _, m in stamped] for t, stamped in expected.items()}


def test_header_channels_and_qos_are_as_registered(written_bag):
    path, _ = written_bag
    with open(path, 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == 'ros2' and header.library.startswith('hcloth_ros')
    schemas = summary.schemas
    channels = {c.topic: c for c in summary.channels.values()}
    assert {t: schemas[c.schema_id].name for t, c in channels.items()} == {
        '/cloth/points': 'sensor_msgs/msg/PointCloud2',
        '/cloth/lod_marker': 'visualization_msgs/msg/Marker',
        '/scene/markers': 'visualization_msgs/msg/MarkerArray',
        '/clock': 'rosgraph_msgs/msg/Clock',
        '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'}
    assert {s.encoding for s in schemas.values()} == {'ros2msg'}
    assert {c.message_encoding for c in channels.values()} == {'cdr'}
    assert schemas[channels['/clock'].schema_id].data.decode() == (
        bag.message_definition('rosgraph_msgs/msg/Clock'))
    assert summary.statistics.message_count == 7
    with open(path, 'rb') as f:     # read start to end: chunks, then the summary and footer
        kinds = [type(r) for r in StreamReader(f, emit_chunks=True).records]
    assert kinds.count(Chunk) == 1 and kinds.count(DataEnd) == 1
    assert Statistics in kinds and kinds[-1] is Footer
    assert summary.statistics.message_end_time == 3_000_000_007

    infinite = {'sec': 9223372036, 'nsec': 854775807}
    points_qos = yaml.safe_load(channels['/cloth/points'].metadata['offered_qos_profiles'])
    assert points_qos == [{
        'history': 'keep_last', 'depth': 5, 'reliability': 'best_effort',
        'durability': 'volatile', 'deadline': infinite, 'lifespan': infinite,
        'liveliness': 'automatic', 'liveliness_lease_duration': infinite,
        'avoid_ros_namespace_conventions': False}]
    scene_qos = yaml.safe_load(channels['/scene/markers'].metadata['offered_qos_profiles'])
    assert (scene_qos[0]['reliability'], scene_qos[0]['durability'], scene_qos[0]['depth']) == (
        'reliable', 'transient_local', 1)
    assert channels['/cloth/points'].metadata['topic_type_hash'] == POINTS_HASH
    assert all(c.metadata['topic_type_hash'].startswith('RIHS01_') and
               len(c.metadata['topic_type_hash']) == 7 + 64 for c in channels.values())


def test_refuses_to_overwrite_an_existing_file(tmp_path):
    path = tmp_path / 'old.mcap'
    path.write_bytes(b'keep me')
    with pytest.raises(FileExistsError, match='refusing to overwrite') as err:
        BagWriter(str(path))
    assert err.value.filename == str(path)
    assert path.read_bytes() == b'keep me'


def test_unwritable_paths_raise_naming_the_path(tmp_path):
    missing = str(tmp_path / 'no_such_dir' / 'run.mcap')
    with pytest.raises(FileNotFoundError, match='cannot create the bag') as err:
        BagWriter(missing)
    assert err.value.filename == missing
    with pytest.raises(ValueError, match='run.bag'):
        BagWriter(str(tmp_path / 'run.bag'))


def test_close_is_idempotent_and_writing_after_it_fails(tmp_path):
    path = str(tmp_path / 'clock.mcap')
    writer = BagWriter(path)
    writer.add_topic('/clock', Clock)
    writer.write('/clock', Clock(clock=Time(sec=4)), 4_000_000_000)
    writer.close()
    writer.close()
    assert writer.closed
    with pytest.raises(ValueError, match='closed'):
        writer.write('/clock', Clock(), 5)
    assert [(r.log_time_ns, r.ros_msg.clock.sec) for r in _read_decoded(path)] == [
        (4_000_000_000, 4)]


def test_misuse_is_refused(tmp_path):
    with BagWriter(str(tmp_path / 'misuse.mcap')) as writer:
        writer.add_topic('/clock', Clock)
        with pytest.raises(ValueError, match='registered already'):
            writer.add_topic('/clock', Clock)
        with pytest.raises(ValueError, match='reliability'):
            writer.add_topic('/other', Clock, qos='fast')
        with pytest.raises(TypeError, match='not a ROS 2 message class'):
            writer.add_topic('/other', 'rosgraph_msgs/msg/Clock')
        with pytest.raises(KeyError, match='/missing'):
            writer.write('/missing', Clock(), 1)
        with pytest.raises(TypeError, match='carries Clock, got Marker'):
            writer.write('/clock', Marker(), 1)
        with pytest.raises(ValueError, match='non-negative'):
            writer.write('/clock', Clock(), -1)
