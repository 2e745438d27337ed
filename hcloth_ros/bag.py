"""
Recording ROS 2 messages to an MCAP file that ``ros2 bag info/play`` and Foxglove read.

:class:`BagWriter` writes the ``ros2`` MCAP profile the way rosbag2's MCAP storage plugin
does: one schema per message type (encoding ``ros2msg``, the full .msg text with its
dependencies), one channel per topic (encoding ``cdr``) carrying the ``offered_qos_profiles``
that ``ros2 bag play`` offers again (and ``topic_type_hash`` when the installed type
description has one), and messages serialised by rclpy.

Times are nanoseconds of the simulation clock: a message's log time and publish time are both
the stamp the caller gives, so a bag plays back on the simulation's own timeline.

:func:`message_definition` and :func:`dependencies` find the .msg files of a type and of every
type it refers to, through the ament index (a ROS 2 install) or ``<sys.prefix>/share`` (the
PyPI wheels).
"""

import errno
import functools
import json
import os
import sys

from ament_index_python.packages import get_package_share_directory
import mcap
from mcap.writer import CompressionType, Writer
from rclpy.serialization import serialize_message


# Field types of the .msg language that are not messages (``string<=N`` is cut to ``string``)
BUILTIN_TYPES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))

# rosbag2 puts this line and ``MSG: pkg/Type`` before the text of each dependency
SEPARATOR = '=' * 80

# A chunk is closed once it holds more than 768 KiB (libmcap's default, so rosbag2's too):
# each cloud of 66,049 points (793 kB) gets a chunk of its own, 4,225-point clouds (51 kB)
# share one by 16. A chunk is held in memory and copied twice when closed, so closing costs
# in proportion to its size: on the 2-core VM, 2 MiB chunks made one write in three take
# 1-7 ms, 4 MiB ones one in six take up to 12-40 ms, for no gain in the mean write time
CHUNK_SIZE = 768 * 1024

# rmw's infinite duration (RMW_DURATION_INFINITE) as rosbag2 writes it: what the middleware
# reports for a publisher that sets no deadline, lifespan or liveliness lease
_INFINITE = (9223372036, 854775807)

_QOS_RELIABILITY = ('reliable', 'best_effort')

_LIBRARY = f'hcloth_ros.bag (mcap {getattr(mcap, "__version__", "unknown")})'


def _split_type(type_name):
    """Return ``(package, name)`` of ``pkg/msg/Type`` or ``pkg/Type``."""
    parts = type_name.split('/')
    if len(parts) not in (2, 3) or not all(parts) or (len(parts) == 3 and parts[1] != 'msg'):
        raise ValueError(f'not a message type name: {type_name!r} (expected pkg/msg/Type)')
    return parts[0], parts[-1]


def _share_directories(package):
    """Yield the share directories that may hold ``package``: ament's, then sys.prefix's."""
    try:
        yield get_package_share_directory(package)
    except (LookupError, OSError):
        pass    # no ROS 2 install (or AMENT_PREFIX_PATH unset): the wheels' place may do
    yield os.path.join(sys.prefix, 'share', package)


def _interface_file(package, name, extension):
    """Return the path of ``<share>/<package>/msg/<name><extension>``, or None."""
    for share in _share_directories(package):
        path = os.path.join(share, 'msg', name + extension)
        if os.path.isfile(path):
            return path
    return None


def _field_dependency(line, package):
    """
    Return the ``pkg/Type`` a .msg line's field refers to, or None.

    None for blank lines, comments and builtin types (constants have builtin types). Arrays
    (``Type[]``, ``Type[<=N]``, ``Type[3]``) refer to their element type; a bare ``Header``
    is ``std_msgs/Header`` and other bare names are of ``package``.
    """
    tokens = line.split('#', 1)[0].split()
    if not tokens:
        return None
    base = tokens[0].split('[', 1)[0].split('<=', 1)[0]
    if base in BUILTIN_TYPES:
        return None
    parts = base.split('/')
    if len(parts) == 1:
        return 'std_msgs/Header' if base == 'Header' else f'{package}/{base}'
    return f'{parts[0]}/{parts[-1]}'


@functools.lru_cache(maxsize=None)
def _load(type_name):
    """Return ``(text, direct dependencies sorted)`` of a message type's .msg file."""
    package, name = _split_type(type_name)
    path = _interface_file(package, name, '.msg')
    if path is None:
        raise LookupError(f'no .msg file for {type_name}: looked in the ament index and in '
                          f'{os.path.join(sys.prefix, "share", package, "msg")}')
    with open(path, encoding='utf-8') as f:
        text = f.read()
    found = {_field_dependency(line, package) for line in text.splitlines()}
    # sorted like rosbag2's std::set, so the schema text is the same as in its bags
    return text, tuple(sorted(found - {None}))


def _append_definitions(type_name, seen, out):
    """Append the .msg text of ``type_name``, then each dependency not in ``seen`` yet."""
    text, direct = _load(type_name)
    out.append(text)
    for dependency in direct:
        if dependency not in seen:
            seen.append(dependency)
            out.append(f'\n{SEPARATOR}\nMSG: {dependency}\n')
            _append_definitions(dependency, seen, out)


def _walk(type_name):
    """Return ``(full definition text, dependencies in the order they appear in it)``."""
    seen, out = [], []
    _append_definitions(type_name, seen, out)
    return ''.join(out), seen


@functools.lru_cache(maxsize=None)
def message_definition(type_name):
    """
    Return the full ``ros2msg`` definition of ``type_name`` (``pkg/msg/Type``).

    The format rosbag2 writes: the type's .msg text, then for every type it depends on,
    directly or not, once each and depth first, a newline, a line of 80 ``=``, a line
    ``MSG: pkg/Type`` and that type's .msg text.
    """
    return _walk(type_name)[0]


def dependencies(type_name):
    """Return the ``pkg/Type`` names ``type_name`` depends on, in definition order."""
    return list(_walk(type_name)[1])


@functools.lru_cache(maxsize=None)
def type_hash(type_name):
    """
    Return the ``RIHS01_<sha256>`` type hash of ``type_name``, or None if not installed.

    Read from the type description rosidl generates next to the .msg file: the hash the
    middleware reports for a publisher of that type and rosbag2 stores as ``topic_type_hash``.
    """
    package, name = _split_type(type_name)
    path = _interface_file(package, name, '.json')
    if path is None:
        return None
    full_name = f'{package}/msg/{name}'
    with open(path, encoding='utf-8') as f:
        hashes = json.load(f).get('type_hashes', [])
    for entry in hashes:
        value = entry.get('hash_string', '')
        if entry.get('type_name') == full_name and value.startswith('RIHS01_'):
            return value
    return None


def _duration_yaml(key):
    """Return the YAML lines of an infinite QoS duration called ``key``."""
    sec, nsec = _INFINITE
    return [f'  {key}:', f'    sec: {sec}', f'    nsec: {nsec}']


def offered_qos_profiles(reliability='reliable', transient_local=False, depth=10):
    """
    Return a channel's ``offered_qos_profiles`` metadata: one publisher's profile.

    A YAML list of profiles as rosbag2 (metadata version 9 and later) writes it: history,
    depth, reliability, durability, deadline, lifespan, liveliness,
    liveliness_lease_duration and avoid_ros_namespace_conventions; durations infinite.
    """
    if reliability not in _QOS_RELIABILITY:
        raise ValueError(f'reliability must be one of {_QOS_RELIABILITY}, got {reliability!r}')
    if int(depth) < 1:
        raise ValueError(f'depth must be at least 1, got {depth}')
    durability = 'transient_local' if transient_local else 'volatile'
    lines = ['- history: keep_last', f'  depth: {int(depth)}',
             f'  reliability: {reliability}', f'  durability: {durability}']
    lines += _duration_yaml('deadline') + _duration_yaml('lifespan')
    lines.append('  liveliness: automatic')
    lines += _duration_yaml('liveliness_lease_duration')
    lines.append('  avoid_ros_namespace_conventions: false')
    return '\n'.join(lines)     # yaml-cpp's Dump ends without a newline


def type_name_of(msg_type):
    """Return ``pkg/msg/Type`` of a generated ROS 2 message class."""
    if not isinstance(msg_type, type) or not hasattr(msg_type, 'get_fields_and_field_types'):
        raise TypeError(f'not a ROS 2 message class: {msg_type!r}')
    package, kind = msg_type.__module__.split('.')[:2]
    return f'{package}/{kind}/{msg_type.__name__}'


def _create(path):
    """Open a new file at ``path`` for binary writing; never truncate an existing one."""
    path = os.fspath(path)
    if not path.endswith('.mcap'):
        raise ValueError(f'{path}: a bag file name must end with .mcap (how ros2 bag and '
                         'Foxglove recognise an MCAP file)')
    try:
        return open(path, 'xb')
    except FileExistsError:
        raise FileExistsError(errno.EEXIST, 'refusing to overwrite an existing file',
                              path) from None
    except OSError as err:
        raise OSError(err.errno, f'cannot create the bag ({err.strerror})', path) from err


class BagWriter:
    """
    Record ROS 2 messages to a new MCAP file, readable by ``ros2 bag`` and Foxglove.

    Register each topic with :meth:`add_topic`, then :meth:`write` messages stamped with
    simulation time in nanoseconds; :meth:`close` (or leaving a ``with`` block) finishes the
    file. Chunks are not compressed (as rosbag2's default).
    """

    def __init__(self, path):
        """Create the file at ``path`` (a new ``.mcap``) and write the MCAP header."""
        self.path = os.fspath(path)
        self._file = _create(self.path)
        try:
            # No compression: on the 2-core VM a 66,049-point cloud took 0.22 ms to write
            # uncompressed, lz4 cut its bytes to 63 % for 1.2 ms more, zstd to a third for
            # 2 ms more. No chunk CRCs (rosbag2's default too): a pass over every byte.
            self._writer = Writer(self._file, chunk_size=CHUNK_SIZE,
                                  compression=CompressionType.NONE, enable_crcs=False)
            self._writer.start(profile='ros2', library=_LIBRARY)
        except BaseException:
            self._file.close()
            raise
        self._schemas = {}      # type name -> schema id
        self._channels = {}     # topic -> (channel id, message class)

    def add_topic(self, topic, msg_type, qos='reliable', transient_local=False, depth=10):
        """
        Register ``topic`` carrying ``msg_type`` (a message class) as a channel.

        ``qos`` (``'reliable'`` or ``'best_effort'``), ``transient_local`` and ``depth`` are
        what a publisher of the topic offers; ``ros2 bag play`` offers them again.
        """
        self._check_open()
        if topic in self._channels:
            raise ValueError(f'topic {topic} is registered already')
        name = type_name_of(msg_type)
        metadata = {'offered_qos_profiles': offered_qos_profiles(qos, transient_local, depth)}
        hash_string = type_hash(name)
        if hash_string is not None:
            metadata['topic_type_hash'] = hash_string
        channel = self._writer.register_channel(topic, 'cdr', self._schema(name), metadata)
        self._channels[topic] = (channel, msg_type)

    def _schema(self, type_name):
        """Return the schema id of ``type_name``, registering its definition once."""
        if type_name not in self._schemas:
            data = message_definition(type_name).encode('utf-8')
            self._schemas[type_name] = self._writer.register_schema(type_name, 'ros2msg', data)
        return self._schemas[type_name]

    def write(self, topic, msg, stamp_ns):
        """
        Write ``msg`` on the registered ``topic`` at ``stamp_ns``.

        ``msg`` is a message of the topic's type, or its serialised bytes (as the node's
        LOD marker comes, :class:`~hcloth_ros.ros_msgs.TriangleMarker`). ``stamp_ns`` is
        the simulation time in nanoseconds (a non-negative int); it becomes both the log
        time and the publish time of the message.
        """
        self._check_open()
        try:
            channel, msg_type = self._channels[topic]
        except KeyError:
            raise KeyError(f'topic {topic} is not registered (call add_topic first)') from None
        if type(msg) is not msg_type and not isinstance(msg, bytes):
            raise TypeError(f'{topic} carries {msg_type.__name__}, got {type(msg).__name__}')
        stamp = int(stamp_ns)
        if stamp < 0:
            raise ValueError(f'stamp_ns must be non-negative, got {stamp_ns}')
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        self._writer.add_message(channel, log_time=stamp, data=data, publish_time=stamp)

    def _check_open(self):
        """Raise ValueError once the bag is closed."""
        if self._file is None:
            raise ValueError(f'{self.path}: the bag is closed')

    def close(self):
        """Finish the file (last chunk, summary, footer) and close it; again does nothing."""
        if self._file is None:
            return
        file, self._file = self._file, None
        try:
            self._writer.finish()
        finally:
            file.close()

    @property
    def closed(self):
        """Whether :meth:`close` has run."""
        return self._file is None

    def __enter__(self):
        """Return the writer itself."""
        return self

    def __exit__(self, *exc_info):
        """Close the bag, also when the block raised."""
        self.close()
