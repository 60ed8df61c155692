"""ROS 1 bags (format 2.0) written by ROS's own Python library, python3-rosbag, with the real
message classes of python3-sensor-msgs."""
import genpy
import rosbag
from sensor_msgs.msg import CompressedImage, Image, Imu

IMU_FRAME_ID = 'imu0'
CAMERA_FRAME_ID = 'cam0'


def write_bag(path, recording, compression='none', png_images=False):
    """The recording as a ROS 1 bag: Imu messages on the IMU's topic and, on the camera's,
    Image messages (mono8), or with png_images CompressedImage ones (format "png", the files'
    bytes) on the camera's topic + '/compressed'. compression: 'none', 'lz4' or 'bz2'."""
    camera_topic = recording.camera_topic + ('/compressed' if png_images else '')
    camera_message = _compressed_image if png_images else _image
    with rosbag.Bag(path, 'w', compression=compression) as bag:
        for kind, index, item in recording.events():
            if kind == 'imu':
                bag.write(recording.imu_topic, _imu(item, index), _time(item.t_ns))
            else:
                bag.write(camera_topic, camera_message(item, index), _time(item.t_ns))


def _time(t_ns):
    return genpy.Time(t_ns // 10**9, t_ns % 10**9)


def _header(message, t_ns, seq, frame_id):
    message.header.seq = seq
    message.header.stamp = _time(t_ns)
    message.header.frame_id = frame_id


def _imu(sample, seq):
    m = Imu()
    _header(m, sample.t_ns, seq, IMU_FRAME_ID)
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = 0.0, 0.0, 0.0, 1.0
    m.orientation_covariance = [-1.0] + [0.0] * 8  # ROS's "no orientation estimate"
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = sample.gyro
    m.angular_velocity_covariance = [0.0] * 9
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = sample.accel
    m.linear_acceleration_covariance = [0.0] * 9
    return m


def _image(frame, seq):
    m = Image()
    _header(m, frame.t_ns, seq, CAMERA_FRAME_ID)
    m.height = frame.height
    m.width = frame.width
    m.encoding = 'mono8'
    m.is_bigendian = 0
    m.step = frame.width
    m.data = frame.pixels
    return m


def _compressed_image(frame, seq):
    m = CompressedImage()
    _header(m, frame.t_ns, seq, CAMERA_FRAME_ID)
    m.format = 'png'
    m.data = frame.png
    return m
