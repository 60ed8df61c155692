"""Decodes the three ROS 2 messages of the bags from CDR for read_back.py, field by field after
the OMG CDR rules (XCDR1, little endian: each primitive aligned to its size from the byte after
the 4-byte encapsulation header), apart from ros2_msgs.py's serializer. Each decoder returns a
tuple shaped as read_back.py's expectations and fails on a byte too many or too few."""
import struct


class CdrError(Exception):
    pass


class CdrReader:
    def __init__(self, data):
        if bytes(data[:4]) != b'\x00\x01\x00\x00':
            raise CdrError(f'encapsulation {bytes(data[:4]).hex()}, not CDR_LE 00010000')
        self.data = data
        self.pos = 4

    def _read(self, fmt, size):
        offset = self.pos - 4  # the alignment origin: the byte after the header
        self.pos += -offset % size
        if self.pos + struct.calcsize(fmt) > len(self.data):
            raise CdrError('message ends inside a field')
        values = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += struct.calcsize(fmt)
        return values

    def uint8(self):
        return self._read('<B', 1)[0]

    def int32(self):
        return self._read('<i', 4)[0]

    def uint32(self):
        return self._read('<I', 4)[0]

    def float64s(self, n):
        return self._read(f'<{n}d', 8)

    def string(self):
        length = self.uint32()  # counts the terminating NUL
        raw = self._read(f'<{length}s', 1)[0]
        if length == 0 or raw[-1:] != b'\x00':
            raise CdrError('string without its terminating NUL')
        return raw[:-1].decode('utf-8')

    def uint8_sequence(self):
        return self._read(f'<{self.uint32()}s', 1)[0]

    def end(self):
        if self.pos != len(self.data):
            raise CdrError(f'{len(self.data) - self.pos} bytes after the last field')


def _header(r):
    return (r.int32(), r.uint32()), r.string()


def imu(data):
    """(stamp, frame_id, orientation, its covariance, angular velocity, its covariance, linear
    acceleration, its covariance) of a sensor_msgs/msg/Imu."""
    r = CdrReader(data)
    stamp, frame_id = _header(r)
    fields = (stamp, frame_id, r.float64s(4), r.float64s(9), r.float64s(3), r.float64s(9),
              r.float64s(3), r.float64s(9))
    r.end()
    return fields


def image(data):
    """(stamp, frame_id, height, width, encoding, is_bigendian, step, data) of a
    sensor_msgs/msg/Image."""
    r = CdrReader(data)
    stamp, frame_id = _header(r)
    fields = (stamp, frame_id, r.uint32(), r.uint32(), r.string(), r.uint8(), r.uint32(),
              r.uint8_sequence())
    r.end()
    return fields


def compressed_image(data):
    """(stamp, frame_id, format, data) of a sensor_msgs/msg/CompressedImage."""
    r = CdrReader(data)
    stamp, frame_id = _header(r)
    fields = (stamp, frame_id, r.string(), r.uint8_sequence())
    r.end()
    return fields
