"""ROS 2 messages written without ROS 2: the .msg definitions (for the schemas MCAP and rosbag2's
sqlite store carry) and a CDR serializer for sensor_msgs/msg/Imu, Image and CompressedImage.

CDR here is what rmw_fastrtps / rosidl_typesupport_fastrtps put in a bag: XCDR1 (plain CDR),
little endian, behind the 4-byte encapsulation header 00 01 00 00 (CDR_LE, options 0)."""
import re
import struct
from dataclasses import dataclass

# The interfaces' fields (ROS 2 rolling's common_interfaces and builtin_interfaces), without the
# installed files' comments: rosbag2's "ros2msg" encoding allows writers to strip them.
MSG_TEXT = {
    'sensor_msgs/msg/Imu': """\
std_msgs/Header header

geometry_msgs/Quaternion orientation
float64[9] orientation_covariance

geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance

geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
""",
    'sensor_msgs/msg/Image': """\
std_msgs/Header header

uint32 height
uint32 width

string encoding

uint8 is_bigendian
uint32 step
uint8[] data
""",
    'sensor_msgs/msg/CompressedImage': """\
std_msgs/Header header

string format

uint8[] data
""",
    'std_msgs/msg/Header': """\
builtin_interfaces/Time stamp

string frame_id
""",
    'geometry_msgs/msg/Quaternion': """\
float64 x 0
float64 y 0
float64 z 0
float64 w 1
""",
    'geometry_msgs/msg/Vector3': """\
float64 x
float64 y
float64 z
""",
    'builtin_interfaces/msg/Time': """\
int32 sec

uint32 nanosec
""",
}

DELIMITER = '=' * 80 + '\n'
# rosbag2's pattern for the type of a field: the first word of a line, before an optional [..].
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
               'int32', 'uint32', 'int64', 'uint64', 'string'}


def full_definition(type_name):
    """The "ros2msg" text of type_name as rosbag2 stores it (its local message definition
    source): the type's .msg, then each dependency not yet written, in sorted order and depth
    first, after a line of 80 '=' and a line 'MSG: <name as the field spelt it>'."""
    seen = set()

    def append(name):
        package = name.split('/')[0]
        text = MSG_TEXT[_canonical(name)]
        for dependency in sorted(_dependencies(text, package)):
            if dependency not in seen:
                seen.add(dependency)
                text += '\n' + DELIMITER + 'MSG: ' + dependency + '\n' + append(dependency)
        return text

    return append(type_name)


def _dependencies(text, package):
    types = {m.group(1) for m in _FIELD_TYPE.finditer(text)} - _PRIMITIVES
    return {t if '/' in t else f'{package}/{t}' for t in types}


def _canonical(name):
    package, *_, base = name.split('/')
    return f'{package}/msg/{base}'


class CdrWriter:
    """A CDR stream following the OMG CDR rules (CORBA 3.x, ch. 9.3; XCDR1 of DDS-XTypes 1.3,
    7.4.1): every primitive aligned to its own size (1, 4 or 8), counted from the first byte
    after the encapsulation header; a string is its uint32 length counting the terminating NUL,
    its bytes and the NUL; a sequence is its uint32 count and its elements; a fixed array is its
    elements alone. No padding follows the last field."""

    def __init__(self):
        self._parts = [b'\x00\x01\x00\x00']  # CDR_LE, options 0
        self._size = 0                       # bytes after the header: the alignment origin

    def _put(self, data):
        self._parts.append(data)
        self._size += len(data)

    def _align(self, n):
        if self._size % n:
            self._put(bytes(n - self._size % n))

    def uint8(self, v):
        self._put(struct.pack('<B', v))

    def int32(self, v):
        self._align(4)
        self._put(struct.pack('<i', v))

    def uint32(self, v):
        self._align(4)
        self._put(struct.pack('<I', v))

    def float64s(self, values):
        """Consecutive float64 fields, or a fixed array float64[N]."""
        self._align(8)
        self._put(struct.pack(f'<{len(values)}d', *values))

    def string(self, s):
        data = s.encode('utf-8') + b'\x00'
        self.uint32(len(data))
        self._put(data)

    def uint8_sequence(self, data):
        self.uint32(len(data))
        self._put(bytes(data))

    def getvalue(self):
        return b''.join(self._parts)


def stamp(t_ns):
    """builtin_interfaces/Time of a nanosecond timestamp."""
    return t_ns // 10**9, t_ns % 10**9


def _header(w, t_ns, frame_id):
    sec, nanosec = stamp(t_ns)
    w.int32(sec)
    w.uint32(nanosec)
    w.string(frame_id)


# orientation unknown: ROS's convention is orientation_covariance[0] = -1.
NO_ORIENTATION = (0.0, 0.0, 0.0, 1.0)
NO_ORIENTATION_COVARIANCE = (-1.0,) + (0.0,) * 8
ZERO_COVARIANCE = (0.0,) * 9


def imu_cdr(sample, frame_id):
    """sensor_msgs/msg/Imu of a recording's ImuSample."""
    w = CdrWriter()
    _header(w, sample.t_ns, frame_id)
    w.float64s(NO_ORIENTATION)
    w.float64s(NO_ORIENTATION_COVARIANCE)
    w.float64s(sample.gyro)
    w.float64s(ZERO_COVARIANCE)
    w.float64s(sample.accel)
    w.float64s(ZERO_COVARIANCE)
    return w.getvalue()


def image_cdr(frame, frame_id):
    """sensor_msgs/msg/Image (mono8) of a recording's Frame."""
    w = CdrWriter()
    _header(w, frame.t_ns, frame_id)
    w.uint32(frame.height)
    w.uint32(frame.width)
    w.string('mono8')
    w.uint8(0)  # is_bigendian
    w.uint32(frame.width)  # step: one byte a pixel, no row padding
    w.uint8_sequence(frame.pixels)
    return w.getvalue()


def compressed_image_cdr(frame, frame_id):
    """sensor_msgs/msg/CompressedImage of a recording's Frame: its PNG file as it is."""
    w = CdrWriter()
    _header(w, frame.t_ns, frame_id)
    w.string('png')
    w.uint8_sequence(frame.png)
    return w.getvalue()


@dataclass(frozen=True)
class Topic:
    name: str
    type: str        # e.g. sensor_msgs/msg/Imu
    definition: str  # its full "ros2msg" text


@dataclass(frozen=True)
class Message:
    topic: Topic
    t_ns: int
    sequence: int  # index of the message on its topic
    data: bytes    # CDR


IMU_FRAME_ID = 'imu0'
CAMERA_FRAME_ID = 'cam0'


def serialize(recording, png_images=False):
    """The recording as ROS 2 messages, in time order (IMU first at equal times): the camera's
    as sensor_msgs/msg/Image on its topic, or with png_images as CompressedImage on the topic
    + '/compressed' (image_transport's name). Returns (topics, messages)."""
    imu = _topic(recording.imu_topic, 'sensor_msgs/msg/Imu')
    if png_images:
        camera = _topic(recording.camera_topic + '/compressed', 'sensor_msgs/msg/CompressedImage')
        camera_cdr = compressed_image_cdr
    else:
        camera = _topic(recording.camera_topic, 'sensor_msgs/msg/Image')
        camera_cdr = image_cdr
    messages = []
    for kind, index, item in recording.events():
        if kind == 'imu':
            messages.append(Message(imu, item.t_ns, index, imu_cdr(item, IMU_FRAME_ID)))
        else:
            messages.append(Message(camera, item.t_ns, index, camera_cdr(item, CAMERA_FRAME_ID)))
    return [imu, camera], messages


def _topic(name, type_name):
    return Topic(name=name, type=type_name, definition=full_definition(type_name))
