"""
Many CDR messages of one layout decoded at once into numpy arrays: a bag's joint states and points.

A driver publishes every sensor_msgs/JointState with the same joint names and every
geometry_msgs/PointStamped with the same frame, so their serialised bytes differ only in the
stamp and the numbers: same length, same bytes elsewhere. Such messages are stacked into one
(n, length) byte array and the stamp and the values read as columns of it, instead of decoding
message by message (about 15 us each in Python). A message whose layout differs from its group's
(other names, another frame) is left to the caller's message-by-message decoder.

CDR: robotenis_ros.cdr.
"""
import struct

import numpy as np
from robotenis_ros.cdr import align, byte_order, joint_state_layout, STAMP, string


def point_layout(data):
    """Return the byte offset of point.x in a geometry_msgs/PointStamped, and the byte order."""
    order = byte_order(data)
    _, pos = string(data, STAMP.stop, order)                  # header.frame_id
    return align(pos, 8), order


def _groups(datas):
    """Yield (indices, stacked bytes (n, length)) of the messages sharing a length."""
    lengths = np.fromiter((len(d) for d in datas), dtype=np.int64, count=len(datas))
    for length in np.unique(lengths):
        index = np.flatnonzero(lengths == length)
        buf = np.frombuffer(b''.join(datas[i] for i in index), dtype=np.uint8)
        yield index, buf.reshape(len(index), int(length))


def _same_layout(buf, start, stop):
    """Return the mask of rows whose bytes in [start, stop) are the first row's."""
    return np.all(buf[:, start:stop] == buf[0, start:stop], axis=1)


def _stamps(buf, order):
    sec = buf[:, 4:8].copy().view(order + 'i4')[:, 0].astype(np.int64)
    nanosec = buf[:, 8:12].copy().view(order + 'u4')[:, 0].astype(np.int64)
    return sec * 1_000_000_000 + nanosec


def _doubles(buf, offset, n, order):
    return buf[:, offset:offset + 8 * n].copy().view(order + 'f8').reshape(len(buf), n)


def points(datas):
    """
    Decode PointStamped messages (list of bytes): (stamp_ns (n,), xyz (n, 3), decoded mask (n,)).

    Rows not decoded (a layout unlike their group's, or not CDR) are zero, False in the mask.
    """
    stamps, xyz = np.zeros(len(datas), np.int64), np.zeros((len(datas), 3))
    ok = np.zeros(len(datas), dtype=bool)
    for index, buf in _groups(datas):
        try:
            offset, order = point_layout(bytes(buf[0]))
        except (ValueError, struct.error, UnicodeDecodeError):
            continue
        if offset + 24 > buf.shape[1]:
            continue
        same = _same_layout(buf, 0, 4) & _same_layout(buf, STAMP.stop, offset)
        rows = index[same]
        stamps[rows], xyz[rows], ok[rows] = _stamps(buf[same], order), \
            _doubles(buf[same], offset, 3, order), True
    return stamps, xyz, ok


def joint_positions(datas, joints):
    """
    Decode JointState messages: (stamp_ns (n,), positions of ``joints`` (n, 3), mask, names).

    ``names``: the name lists seen in the groups decoded. Rows not decoded (another layout, not
    CDR) and rows whose names lack one of ``joints`` are False in the mask.
    """
    stamps, values = np.zeros(len(datas), np.int64), np.zeros((len(datas), len(joints)))
    ok = np.zeros(len(datas), dtype=bool)
    seen = set()
    for index, buf in _groups(datas):
        try:
            layout = joint_state_layout(bytes(buf[0]))
        except ValueError:
            continue
        names, order, (offset, n) = layout.names, layout.order, layout.arrays['position']
        seen.add(names)
        if n != len(names) or offset + 8 * n > buf.shape[1] or not set(joints) <= set(names):
            continue
        same = _same_layout(buf, 0, 4) & _same_layout(buf, STAMP.stop, offset)
        rows = index[same]
        columns = [names.index(j) for j in joints]
        stamps[rows] = _stamps(buf[same], order)
        values[rows] = _doubles(buf[same], offset, n, order)[:, columns]
        ok[rows] = True
    return stamps, values, ok, seen
