"""A recording in the EuRoC layout, read into memory: the IMU's samples, the camera's frames (raw
pixels and the PNG file's bytes) and the topics the Kalibr descriptions name.

    DIR/mav0/imu0/data.csv   #timestamp [ns], gyro x y z [rad/s], accel x y z [m/s^2]
    DIR/mav0/cam0/data.csv   #timestamp [ns], filename (in DIR/mav0/cam0/data/)
    DIR/imu.yaml             rostopic: /imu0
    DIR/camchain.yaml        cam0: {rostopic: /cam0/image_raw, ...}
"""
import os
import struct
from dataclasses import dataclass

import yaml

DEFAULT_IMU_TOPIC = '/imu0'
DEFAULT_CAMERA_TOPIC = '/cam0/image_raw'
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


@dataclass(frozen=True)
class ImuSample:
    t_ns: int
    gyro: tuple   # rad/s, x y z
    accel: tuple  # m/s^2, x y z


@dataclass(frozen=True)
class Frame:
    t_ns: int
    width: int
    height: int
    pixels: bytes  # 8-bit grey, row by row, no padding
    png: bytes     # the file as it is on disk


@dataclass(frozen=True)
class Recording:
    path: str
    imu_topic: str
    camera_topic: str
    imu: list
    frames: list

    def events(self):
        """Every sample and frame as (kind, index on its topic, item), merged by time; at equal
        times the IMU's sample first (the order every output keeps)."""
        keyed = [(s.t_ns, 0, i, 'imu', s) for i, s in enumerate(self.imu)]
        keyed += [(f.t_ns, 1, i, 'camera', f) for i, f in enumerate(self.frames)]
        keyed.sort(key=lambda k: k[:3])
        return [(kind, index, item) for _, _, index, kind, item in keyed]


def load(path):
    """Reads the recording at path (raises ValueError on anything malformed)."""
    mav0 = os.path.join(path, 'mav0')
    imu = [_imu_sample(row) for row in _csv_rows(os.path.join(mav0, 'imu0', 'data.csv'))]
    frames = [_frame(os.path.join(mav0, 'cam0', 'data'), row)
              for row in _csv_rows(os.path.join(mav0, 'cam0', 'data.csv'))]
    return Recording(path=os.path.abspath(path),
                     imu_topic=_topic(os.path.join(path, 'imu.yaml'), (), DEFAULT_IMU_TOPIC),
                     camera_topic=_topic(os.path.join(path, 'camchain.yaml'), ('cam0',),
                                         DEFAULT_CAMERA_TOPIC),
                     imu=imu, frames=frames)


def _csv_rows(path):
    with open(path, encoding='utf-8') as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith('#'):
                yield [field.strip() for field in line.split(',')]


def _imu_sample(row):
    if len(row) != 7:
        raise ValueError(f'IMU row of {len(row)} fields, not 7: {row}')
    # float() of the shortest round-trip decimals the recorder writes gives back its doubles.
    values = tuple(float(v) for v in row[1:])
    return ImuSample(t_ns=_timestamp(row[0]), gyro=values[:3], accel=values[3:])


def _frame(image_dir, row):
    if len(row) != 2:
        raise ValueError(f'camera row of {len(row)} fields, not 2: {row}')
    with open(os.path.join(image_dir, row[1]), 'rb') as f:
        png = f.read()
    width, height = png_size(png)
    return Frame(t_ns=_timestamp(row[0]), width=width, height=height,
                 pixels=_decode_grey(png, width, height), png=png)


def _timestamp(text):
    t = int(text)
    if t < 0:  # MCAP's log times and rosbag2's timestamps are unsigned
        raise ValueError(f'negative timestamp {t}')
    return t


def png_size(png):
    """Width and height from the IHDR chunk; only 8-bit greyscale is accepted (mono8)."""
    if png[:8] != PNG_SIGNATURE or png[12:16] != b'IHDR':
        raise ValueError('not a PNG file')
    width, height, depth, colour = struct.unpack('>IIBB', png[16:26])
    if (depth, colour) != (8, 0):
        raise ValueError(f'PNG of bit depth {depth}, colour type {colour}: not 8-bit grey')
    return width, height


def _decode_grey(png, width, height):
    # OpenCV's codec (libpng), not ours: the bags then carry pixels decoded independently of
    # the C++ reader's own PNG code.
    import cv2
    import numpy as np
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint8 or image.shape != (height, width):
        raise ValueError('PNG did not decode to its IHDR size in 8-bit grey')
    return image.tobytes()


def _topic(yaml_path, keys, default):
    if not os.path.exists(yaml_path):
        return default
    with open(yaml_path, encoding='utf-8') as f:
        node = yaml.safe_load(f) or {}
    for key in keys:
        node = node.get(key) or {}
    return node.get('rostopic') or default
