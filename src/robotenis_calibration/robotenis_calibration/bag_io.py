"""
rosbag2 bags with MCAP storage: writing a session, and reading whatever of a bag survived.

Writing (BagWriter): rosbag2 format version 9, MCAP storage with zstd-compressed chunks (what
rosbag2's own MCAP plugin writes), so ``ros2 bag info/play`` and Foxglove open the bags. Messages
are stored as the CDR bytes the caller gives. The project's own types (robotenis_interfaces) are
registered in the typestore from their .msg files, found in the installed interfaces package or,
without a build, in the source tree.

Reading (BagReader): rosbags' AnyReader on a whole bag. A bag whose recorder died has an MCAP file
cut short (no footer) and maybe no metadata.yaml; AnyReader refuses it, so the reader falls back to
the ``mcap`` library's stream reader, which yields every whole record before the cut (the chunk
being written when the file was cut is lost), and says in ``notes`` how many messages it recovered.
Message times: the header stamp for messages that have a header (when the recorder stamped it),
otherwise the time the message was recorded.
"""
from collections import Counter
import functools
import os
from pathlib import Path
import struct
from typing import NamedTuple

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.serde import SerdeError
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

INTERFACES = 'robotenis_interfaces'


def interface_msg_dir():
    """Locate robotenis_interfaces' .msg files: installed share folder, else the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory
        folder = os.path.join(get_package_share_directory(INTERFACES), 'msg')
    except Exception:  # unbuilt, or ament_index not importable: the source tree has the same files
        here = os.path.dirname(os.path.realpath(__file__))
        folder = os.path.join(here, '..', '..', INTERFACES, 'msg')
    if not os.path.isdir(folder):
        raise FileNotFoundError(f'{INTERFACES}: no msg folder'
                                f' (looked in {os.path.normpath(folder)})')
    return folder


@functools.lru_cache(maxsize=1)
def typestore():
    """Return the ROS 2 Jazzy typestore plus the robotenis_interfaces messages."""
    store = get_typestore(Stores.ROS2_JAZZY)
    folder = interface_msg_dir()
    types = {}
    for name in sorted(os.listdir(folder)):
        if name.endswith('.msg'):
            with open(os.path.join(folder, name)) as f:
                types.update(get_types_from_msg(f.read(), f'{INTERFACES}/msg/{name[:-4]}'))
    store.register(types)
    return store


def png(pixels):
    """Encode a mono8 (h, w) uint8 image array as lossless PNG for sensor_msgs/CompressedImage."""
    import cv2
    ok, data = cv2.imencode('.png', pixels)
    if not ok:
        raise ValueError(f'cannot encode an image of shape {pixels.shape}'
                         f' and type {pixels.dtype} as PNG')
    return data.tobytes()


PNG_FORMAT = 'mono8; png compressed mono8'   # CompressedImage.format of a PNG of a mono8 image


def serialize(msg, type_name):
    """Return the CDR bytes of a rosbags message object."""
    return bytes(typestore().serialize_cdr(msg, type_name))


class BagWriter:
    """Records CDR messages to a new rosbag2 bag directory (MCAP, zstd chunks)."""

    def __init__(self, path):
        if os.path.exists(path):
            raise FileExistsError(f'{path}: exists already; a bag is never overwritten')
        self._writer = Writer(Path(path), version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.open()
        self._connections = {}
        self.path = str(path)

    def add_topic(self, topic, type_name):
        """Declare a topic and its type (e.g. 'sensor_msgs/msg/JointState') before any write."""
        if type_name not in typestore().types:
            raise ValueError(f'{topic}: unknown message type {type_name!r}')
        self._connections[topic] = self._writer.add_connection(topic, type_name,
                                                               typestore=typestore())

    def write(self, topic, stamp_ns, data):
        """Record one message: its CDR bytes, at ``stamp_ns`` (ns)."""
        if topic not in self._connections:
            raise ValueError(f'{topic}: not declared with add_topic')
        self._writer.write(self._connections[topic], int(stamp_ns), bytes(data))

    def close(self):
        """Finish the bag (footer, metadata.yaml); closing twice does nothing."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class Record(NamedTuple):
    """One stored message: topic, type name, time recorded (ns) and CDR bytes."""

    topic: str
    type_name: str
    log_ns: int
    data: bytes


class BagReader:
    """A rosbag2 bag folder opened for reading; ``topics`` {topic: type}, ``counts`` {topic: n}."""

    def __init__(self, bag_dir):
        self.path = Path(bag_dir)
        if not self.path.is_dir():
            raise FileNotFoundError(f'{bag_dir}: no such bag directory')
        self.notes = []
        self._any = None
        self._files = sorted(self.path.glob('*.mcap'))
        try:
            self._any = AnyReader([self.path], default_typestore=typestore())
            self._any.open()
        except (AnyReaderError, OSError) as e:
            self._any = None
            if not self._files:
                raise ValueError(f'{bag_dir}: not a readable rosbag2 bag ({e})') from e
            self.notes.append(f'{bag_dir}: cannot be read whole ({e});'
                              ' reading every whole MCAP record')
            self.topics, self.counts = self._scan()
        else:
            self.topics = {c.topic: c.msgtype for c in self._any.connections}
            self.counts = {t: sum(c.msgcount for c in self._any.connections if c.topic == t)
                           for t in self.topics}

    def close(self):
        if self._any is not None:
            self._any.close()
            self._any = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _stream(self, seen=None):
        """
        Yield (topic, type name, mcap Message) of every whole message record of the MCAP files.

        In file order; the topics declared on the way go to ``seen`` {topic: type}.
        """
        for path in self._files:
            schemas, channels = {}, {}
            with open(path, 'rb') as f:
                try:
                    for record in StreamReader(f).records:
                        if isinstance(record, Schema):
                            schemas[record.id] = record.name
                        elif isinstance(record, Channel):
                            channels[record.id] = (record.topic, schemas.get(record.schema_id, ''))
                            if seen is not None:
                                seen[record.topic] = channels[record.id][1]
                        elif isinstance(record, Message) and record.channel_id in channels:
                            yield (*channels[record.channel_id], record)
                except (McapError, struct.error):
                    continue  # the cut: every whole record before it has been read

    def _scan(self):
        """Scan a bag AnyReader refused for topics, types, counts (one pass over its records)."""
        topics = {}
        counts = Counter(topic for topic, _, _ in self._stream(topics))
        self.notes.append(f'{sum(counts.values())} messages recovered from {self.path}'
                          ' (whole records only)')
        return topics, {t: counts.get(t, 0) for t in topics}

    def records(self, topics=None, progress=None, steps=100):
        """
        Yield the stored messages of ``topics`` (all when None) as Records.

        Time order for a whole bag, file order for a truncated one. ``progress(done, total)`` is
        called ``steps`` times on the way.
        """
        wanted = set(self.topics) if topics is None else set(topics) & set(self.topics)
        total = sum(self.counts[t] for t in wanted)
        step = max(1, total // steps)
        for done, record in enumerate(self._records(wanted), start=1):
            if progress and done % step == 0:
                progress(done, total)
            yield record

    def _records(self, wanted):
        if self._any is not None:
            connections = [c for c in self._any.connections if c.topic in wanted]
            for c, log_ns, data in self._any.messages(connections=connections):
                yield Record(c.topic, c.msgtype, log_ns, bytes(data))
        else:
            for topic, type_name, m in self._stream():
                if topic in wanted:
                    yield Record(topic, type_name, m.log_time, bytes(m.data))

    def messages(self, topics=None, progress=None, steps=100):
        """
        Yield (topic, type name, stamp_ns, message) of ``topics``, deserialized.

        The stamp is the header stamp when the message has a non-zero one, the recording time
        otherwise.
        """
        broken = Counter()
        for r in self.records(topics, progress, steps):
            msg = decode(r)
            if msg is None:
                broken[r.topic] += 1       # a corrupt record: skip it, say so once per topic below
                continue
            yield r.topic, r.type_name, stamp_ns(msg, r.log_ns), msg
        self.note_broken(broken)

    def note_broken(self, broken):
        """Say in ``notes`` how many messages of each topic could not be decoded."""
        for topic, n in broken.items():
            self.notes.append(f'{topic}: {n} message(s) could not be decoded and were skipped')


def decode(record):
    """
    Return the message of a Record, deserialized; None when its bytes are corrupt.

    Raises
    ------
    ValueError
        if its type is not known to the typestore.

    """
    try:
        fast = FAST_DECODERS.get(record.type_name)
        return fast(record.data) if fast else \
            typestore().deserialize_cdr(record.data, record.type_name)
    except KeyError as e:
        raise ValueError(f'{record.topic}: message type {record.type_name!r}'
                         ' is not known to the typestore') from e
    except (SerdeError, struct.error, ValueError):
        return None


def stamp_ns(msg, log_ns):
    """Return ``msg``'s header stamp in ns, or ``log_ns`` when it has no header or a zero stamp."""
    header = getattr(msg, 'header', None)
    if header is None or (header.stamp.sec == 0 and header.stamp.nanosec == 0):
        return log_ns
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


class _Stamp(NamedTuple):
    sec: int
    nanosec: int


class _Header(NamedTuple):
    stamp: _Stamp
    frame_id: str


class JointStateMsg(NamedTuple):
    """sensor_msgs/JointState as decoded by ``decode_joint_state`` (sequences as tuples)."""

    header: _Header
    name: tuple
    position: tuple
    velocity: tuple
    effort: tuple


def decode_joint_state(data):
    """
    Decode a sensor_msgs/JointState from its CDR bytes (XCDR1, either byte order).

    Written out because the typestore's decoder is strict where serializers differ: rclpy's Fast
    CDR does not pad before an empty float64 sequence, so a JointState with an empty ``effort``
    (most drivers', and ours) fails its size check. Alignment is relative to the end of the 4-byte
    encapsulation, and a float64 sequence aligns to 8 only when it has elements.
    """
    data = bytes(data)
    if len(data) < 4 or data[1] not in (0, 1):
        raise ValueError('not a CDR encapsulated message')
    order = '<' if data[1] == 1 else '>'
    pos = 4

    def align(n):
        nonlocal pos
        pos += (-(pos - 4)) % n

    def uint32():
        nonlocal pos
        align(4)
        (value,) = struct.unpack_from(order + 'I', data, pos)
        pos += 4
        return value

    def string():
        nonlocal pos
        n = uint32()
        text = data[pos:pos + n].rstrip(b'\0').decode()
        pos += n
        return text

    def doubles():
        nonlocal pos
        n = uint32()
        if n == 0:
            return ()
        align(8)
        values = struct.unpack_from(f'{order}{n}d', data, pos)
        pos += 8 * n
        return values

    sec, nanosec = struct.unpack_from(order + 'iI', data, pos)
    pos += 8
    header = _Header(_Stamp(sec, nanosec), string())
    names = tuple(string() for _ in range(uint32()))
    msg = JointStateMsg(header, names, doubles(), doubles(), doubles())
    if pos > len(data):
        raise ValueError('JointState: message cut short')
    return msg


FAST_DECODERS = {'sensor_msgs/msg/JointState': decode_joint_state}
