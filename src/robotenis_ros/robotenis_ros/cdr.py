"""
Serialized (CDR) messages read and written without building them: the fields a node needs.

A raw subscription takes a message's bytes; rclpy's deserialization of a 640x480 mono8
sensor_msgs/Image copies its pixels into a new array.array (0.55 ms a frame here, a third of the
sphere detector's fast method), where ``image`` views them in the bytes as they came. The
simulator and the controller exchange a sensor_msgs/JointState each way every 1 ms step of a
lockstep session: ``JointStateReader`` and ``JointStateWriter`` read and write their bytes (each
side's CPU per round trip 156-180 us, against 287-321 us with rclpy's messages: ``./robotenis
bench transport``).

CDR (XCDR1): a 4-byte encapsulation header (byte 1: 1 little endian, 0 big endian), then the
fields, each aligned to its size relative to the end of the encapsulation; a string is its uint32
length (with the terminating NUL) and its bytes.
"""
from dataclasses import dataclass
import struct

import numpy as np

HEADER = 4                 # the encapsulation
STAMP = slice(4, 12)       # std_msgs/Header's builtin_interfaces/Time: int32 sec, uint32 nanosec
MONO8 = ('mono8', '8UC1')
JOINT_ARRAYS = ('position', 'velocity', 'effort')     # sensor_msgs/JointState's, in order
ENCAPSULATION_LE = b'\x00\x01\x00\x00'               # CDR little endian, as rclpy writes


def align(pos, n):
    """Return the first offset from ``pos`` aligned to ``n`` bytes (after the encapsulation)."""
    return pos + (-(pos - HEADER)) % n


def uint32(data, pos, order):
    """Return the uint32 at the first aligned offset from ``pos``, and the offset after it."""
    pos = align(pos, 4)
    return struct.unpack_from(order + 'I', data, pos)[0], pos + 4


def string(data, pos, order):
    """Return the string at ``pos`` and the offset after it."""
    n, pos = uint32(data, pos, order)
    if pos + n > len(data):
        raise ValueError('CDR string runs past the end of the message')
    return bytes(data[pos:pos + n]).rstrip(b'\0').decode(), pos + n


def byte_order(data):
    """Return the struct byte order ('<' or '>') of a CDR encapsulated message."""
    if len(data) < HEADER or data[1] not in (0, 1):
        raise ValueError('not a CDR encapsulated message')
    return '<' if data[1] == 1 else '>'


def mono8_pixels(data, encoding, height, width, step):
    """
    Return the (height, width) uint8 view of an image's rows of ``step`` bytes in ``data``.

    Raises
    ------
    ValueError
        if the encoding is not mono8 or the data is shorter than the image.

    """
    if encoding not in MONO8:
        raise ValueError(f'image encoding {encoding!r} is not mono8')
    if step < width or len(data) < step * height:
        raise ValueError(f'image data too short for {width}x{height} (step {step}, '
                         f'{len(data)} bytes)')
    rows = np.frombuffer(data, dtype=np.uint8, count=step * height)
    return rows.reshape(height, step)[:, :width]


@dataclass(frozen=True)
class Image:
    """A sensor_msgs/Image's stamp, frame and mono8 pixels (a read-only view of its bytes)."""

    sec: int
    nanosec: int
    frame_id: str
    pixels: np.ndarray         # (height, width) uint8


def image(data):
    """
    Read a serialized mono8 sensor_msgs/Image.

    Raises
    ------
    ValueError
        if the bytes are not an Image's, or from ``mono8_pixels``.

    """
    order = byte_order(data)
    try:
        sec, nanosec = struct.unpack_from(order + 'iI', data, STAMP.start)
        frame_id, pos = string(data, STAMP.stop, order)
        height, pos = uint32(data, pos, order)
        width, pos = uint32(data, pos, order)
        encoding, pos = string(data, pos, order)
        step, pos = uint32(data, pos + 1, order)          # after is_bigendian (uint8)
        size, pos = uint32(data, pos, order)
    except (ValueError, struct.error, UnicodeDecodeError) as e:
        raise ValueError(f'not a serialized sensor_msgs/Image ({e})') from None
    pixels = mono8_pixels(memoryview(data)[pos:pos + size], encoding, height, width, step)
    return Image(sec, nanosec, frame_id, pixels)


@dataclass(frozen=True)
class JointStateLayout:
    """Where a serialized sensor_msgs/JointState's names and arrays lie."""

    order: str                 # struct byte order
    names: tuple
    arrays: dict               # field (JOINT_ARRAYS) -> (offset of its first double, count)
    size: int                  # bytes of the message (CDR, without any trailing padding)


def joint_state_layout(data):
    """
    Read a serialized sensor_msgs/JointState's layout (JointStateLayout).

    Raises
    ------
    ValueError
        if the bytes are not a JointState's.

    """
    order = byte_order(data)
    try:
        _, pos = string(data, STAMP.stop, order)               # header.frame_id
        count, pos = uint32(data, pos, order)
        names = []
        for _ in range(count):
            name, pos = string(data, pos, order)
            names.append(name)
        arrays = {}
        for field in JOINT_ARRAYS:
            n, pos = uint32(data, pos, order)
            pos = align(pos, 8) if n else pos
            arrays[field] = (pos, n)
            pos += 8 * n
    except (ValueError, struct.error, UnicodeDecodeError) as e:
        raise ValueError(f'not a serialized sensor_msgs/JointState ({e})') from None
    if pos > len(data):
        raise ValueError('not a serialized sensor_msgs/JointState (its arrays run past the end)')
    return JointStateLayout(order, tuple(names), arrays, pos)


class JointStateReader:
    """
    The stamp, positions and velocities of ``joints`` from JointState CDR bytes, one at a time.

    The layout (byte order, names, where the arrays lie) is read once per message length and reused
    while a message's bytes other than its stamp and its numbers are the same; any other message
    is read afresh. A few us a message, against about 30 us for rclpy's deserialization and
    picking the joints by name.
    """

    def __init__(self, joints):
        self.joints = tuple(joints)
        self._plans = {}       # length -> (fixed byte runs, byte order, readers of the fields)

    def read(self, data):
        """
        Return (sec, nanosec, positions, velocities); None if the bytes are not a JointState.

        positions, velocities: tuples of floats in the joints' order; None where the field does
        not hold one value per name or a joint is missing.
        """
        plan = self._plans.get(len(data))
        if plan is None or any(data[a:b] != run for a, b, run in plan[0]):
            plan = self._learn(bytes(data))
            if plan is None:
                return None
        _, order, fields = plan
        sec, nanosec = struct.unpack_from(order + 'iI', data, STAMP.start)
        return (sec, nanosec) + tuple(field and _pick(struct.unpack_from(field[0], data,
                                                                         field[1]), field[2])
                                      for field in fields)

    def _learn(self, data):
        try:
            layout = joint_state_layout(data)
        except ValueError:
            return None
        numbers = [STAMP] + [slice(offset, offset + 8 * n)
                             for offset, n in layout.arrays.values() if n]
        edges = [0] + [b for s in numbers for b in (s.start, s.stop)] + [len(data)]
        fixed = [(a, b, data[a:b]) for a, b in zip(edges[::2], edges[1::2]) if b > a]
        named = len(layout.names) and set(self.joints) <= set(layout.names)
        columns = tuple(layout.names.index(j) for j in self.joints) if named else ()
        fields = []
        for field in JOINT_ARRAYS[:2]:
            offset, n = layout.arrays[field]
            ok = named and n == len(layout.names)
            fields.append((f'{layout.order}{n}d', offset, columns) if ok else None)
        plan = (fixed, layout.order, tuple(fields))
        self._plans[len(data)] = plan
        return plan


def _pick(values, columns):
    return tuple(values[c] for c in columns)


class JointStateWriter:
    """
    sensor_msgs/JointState CDR bytes of fixed ``joints`` and ``fields``, as a publisher sends them.

    The message's bytes are made once; each call packs the stamp and the numbers into a copy.
    ``fields``: of JOINT_ARRAYS, those that hold one value per joint (the others are empty).
    """

    def __init__(self, joints, fields=('position', 'velocity'), frame_id=''):
        unknown = set(fields) - set(JOINT_ARRAYS)
        if unknown:
            raise ValueError(f'JointState has no field {sorted(unknown)[0]!r}')
        buf = bytearray(ENCAPSULATION_LE + bytes(8))            # the stamp: packed per message
        _put_string(buf, frame_id)
        _put_uint32(buf, len(joints))
        for name in joints:
            _put_string(buf, name)
        self.fields, self.slots = tuple(f for f in JOINT_ARRAYS if f in fields), {}
        for field in JOINT_ARRAYS:
            n = len(joints) if field in fields else 0
            _put_uint32(buf, n)
            if n:
                buf.extend(bytes(align(len(buf), 8) - len(buf)))
                self.slots[field] = len(buf)
                buf.extend(bytes(8 * n))
        self.template, self.format = bytes(buf), f'<{len(joints)}d'

    def __call__(self, sec, nanosec, **values):
        """Return the bytes of a JointState stamped (sec, nanosec) with ``values`` per field."""
        if set(values) != set(self.fields):
            raise ValueError(f'JointStateWriter: expected the fields {", ".join(self.fields)}, '
                             f'got {", ".join(sorted(values)) or "none"}')
        buf = bytearray(self.template)
        struct.pack_into('<iI', buf, STAMP.start, sec, nanosec)
        for field, offset in self.slots.items():
            struct.pack_into(self.format, buf, offset, *values[field])
        return bytes(buf)


def _put_uint32(buf, value):
    buf.extend(bytes(align(len(buf), 4) - len(buf)))
    buf.extend(struct.pack('<I', value))


def _put_string(buf, text):
    raw = text.encode() + b'\0'
    _put_uint32(buf, len(raw))
    buf.extend(raw)
