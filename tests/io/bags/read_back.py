#!/usr/bin/python3
"""Reads back what write_bags.py wrote and checks it against the recording, exactly:

    read_back.py OUT_DIR [--recording DIR]

- ROS 1 bags through python3-rosbag's reader (messages decoded from the definitions the bag
  carries): chunk compression, topics and types, every IMU value and every pixel (or PNG byte),
  header stamps, seq and frame ids, bag times;
- MCAP files through mcap_reader.py (its checks of the records, CRCs, indexes and summary), then
  every message decoded by cdr_reader.py, in order, with its log and publish time and sequence;
  and the "rosbag2" Metadata record;
- the sqlite bag through Python's sqlite3: integrity, rosbag2's tables, topics, definitions,
  every message in order; and its metadata row;
- each rosbag2 folder's metadata.yaml through PyYAML, against the values rosbag2 would write.

The recording is the one write_bags.yaml names unless --recording says another. Prints one line
for each output and exits 1 if any does not hold."""
import argparse
import os
import sqlite3
import sys

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import cdr_reader  # noqa: E402
import mcap_reader  # noqa: E402
import recording as recording_io  # noqa: E402
from write_bags import MANIFEST, OUTPUTS  # noqa: E402

IMU_FRAME_ID = 'imu0'
CAMERA_FRAME_ID = 'cam0'
IMU_TYPE = 'sensor_msgs/msg/Imu'


class Mismatch(Exception):
    pass


def expect(condition, message):
    if not condition:
        raise Mismatch(message)


# What every output must hold, as the decoders' tuples.
def stamp(t_ns):
    return t_ns // 10**9, t_ns % 10**9


def expected_imu(s):
    return (stamp(s.t_ns), IMU_FRAME_ID, (0.0, 0.0, 0.0, 1.0), (-1.0,) + (0.0,) * 8,
            tuple(s.gyro), (0.0,) * 9, tuple(s.accel), (0.0,) * 9)


def expected_image(f):
    return (stamp(f.t_ns), CAMERA_FRAME_ID, f.height, f.width, 'mono8', 0, f.width, f.pixels)


def expected_compressed(f):
    return stamp(f.t_ns), CAMERA_FRAME_ID, 'png', f.png


FIELD_NAMES = {
    'sensor_msgs/msg/Imu': ('header.stamp', 'header.frame_id', 'orientation',
                            'orientation_covariance', 'angular_velocity',
                            'angular_velocity_covariance', 'linear_acceleration',
                            'linear_acceleration_covariance'),
    'sensor_msgs/msg/Image': ('header.stamp', 'header.frame_id', 'height', 'width', 'encoding',
                              'is_bigendian', 'step', 'data'),
    'sensor_msgs/msg/CompressedImage': ('header.stamp', 'header.frame_id', 'format', 'data'),
}


class Expected:
    """The recording's messages as an output of png_images or not should hold them."""

    def __init__(self, rec, png_images):
        self.rec = rec
        self.imu_topic = rec.imu_topic
        if png_images:
            self.camera_topic = rec.camera_topic + '/compressed'
            self.camera_type = 'sensor_msgs/msg/CompressedImage'
            self.camera_fields, self.decode_camera = expected_compressed, \
                cdr_reader.compressed_image
        else:
            self.camera_topic = rec.camera_topic
            self.camera_type = 'sensor_msgs/msg/Image'
            self.camera_fields, self.decode_camera = expected_image, cdr_reader.image
        self.counts = {self.imu_topic: len(rec.imu), self.camera_topic: len(rec.frames)}
        times = [s.t_ns for s in rec.imu] + [f.t_ns for f in rec.frames]
        self.start = min(times, default=0)
        self.duration = max(times, default=0) - self.start

    def events(self):
        """(topic, index on it, log time, expected fields) in the outputs' order."""
        for kind, index, item in self.rec.events():
            if kind == 'imu':
                yield self.imu_topic, index, item.t_ns, expected_imu(item)
            else:
                yield self.camera_topic, index, item.t_ns, self.camera_fields(item)

    def decode(self, topic, data):
        return (cdr_reader.imu if topic == self.imu_topic else self.decode_camera)(data)

    def field_names(self, topic):
        return FIELD_NAMES[IMU_TYPE if topic == self.imu_topic else self.camera_type]

    def summary(self):
        return ', '.join(f'{n} {t}' for t, n in self.counts.items())


def compare_fields(got, want, what, names):
    if got != want:
        for name, g, w in zip(names, got, want):
            expect(g == w, f'{what}: {name} is {_describe(g, w)}')
        raise Mismatch(f'{what}: {len(got)} fields, expected {len(want)}')


def _describe(got, want):
    if isinstance(got, bytes) and isinstance(want, bytes):
        at = next((i for i, (g, w) in enumerate(zip(got, want)) if g != w),
                  min(len(got), len(want)))
        return f'{len(got)} bytes differing from byte {at} on, expected {len(want)} bytes'
    return f'{got!r}, expected {want!r}'


# ROS 1 ------------------------------------------------------------------------------------------
ROS1_TYPES = {'sensor_msgs/msg/Imu': 'sensor_msgs/Imu',
              'sensor_msgs/msg/Image': 'sensor_msgs/Image',
              'sensor_msgs/msg/CompressedImage': 'sensor_msgs/CompressedImage'}


def ros1_fields(msg):
    h = msg.header
    head = ((h.stamp.secs, h.stamp.nsecs), h.frame_id)
    if msg._type == 'sensor_msgs/Imu':
        q, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        return head + ((q.x, q.y, q.z, q.w), tuple(msg.orientation_covariance),
                       (w.x, w.y, w.z), tuple(msg.angular_velocity_covariance),
                       (a.x, a.y, a.z), tuple(msg.linear_acceleration_covariance))
    if msg._type == 'sensor_msgs/Image':
        return head + (msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step,
                       bytes(msg.data))
    return head + (msg.format, bytes(msg.data))


def check_ros1(path, exp, compression):
    import rosbag
    with rosbag.Bag(path) as bag:
        info = bag.get_compression_info()
        expect(info.compression == compression,
               f'chunks compressed {info.compression}, expected {compression}')
        topics = bag.get_type_and_topic_info().topics
        want = {exp.imu_topic: (ROS1_TYPES[IMU_TYPE], exp.counts[exp.imu_topic]),
                exp.camera_topic: (ROS1_TYPES[exp.camera_type], exp.counts[exp.camera_topic])}
        got = {t: (i.msg_type, i.message_count) for t, i in topics.items()}
        expect(got == want, f'topics {got}, expected {want}')
        received = {exp.imu_topic: [], exp.camera_topic: []}
        last = None
        # rosbag orders by time but not the topics' messages of equal times: compare by topic.
        for topic, msg, t in bag.read_messages():
            expect(last is None or t >= last, f'bag time {t} before {last}')
            last = t
            received[topic].append((msg, t.to_nsec()))
    for topic, index, t_ns, fields in exp.events():
        msg, bag_time = received[topic][index]
        what = f'{topic} #{index}'
        expect(bag_time == t_ns, f'{what}: bag time {bag_time}, expected {t_ns}')
        expect(msg.header.seq == index, f'{what}: header.seq {msg.header.seq}')
        compare_fields(ros1_fields(msg), fields, what, exp.field_names(topic))
    return f'{exp.summary()}; {compression} chunks'


# ROS 2 ------------------------------------------------------------------------------------------
def check_mcap(path, exp, compression):
    m = mcap_reader.read(path)
    expect(m.profile == 'ros2', f'profile {m.profile!r}')
    expect(m.compressions == {compression}, f'chunk compressions {m.compressions}')
    expect(not m.zero_crcs, f'CRCs left out (0): {", ".join(m.zero_crcs[:3])}')
    channels = {}
    for channel_id, (schema_id, topic, encoding, metadata) in m.channels.items():
        name, schema_encoding, _ = m.schemas[schema_id]
        expect(encoding == 'cdr' and schema_encoding == 'ros2msg',
               f'{topic}: message encoding {encoding}, schema encoding {schema_encoding}')
        expect('offered_qos_profiles' in metadata, f'{topic}: no offered_qos_profiles')
        channels[channel_id] = (topic, name)
    want = {exp.imu_topic: IMU_TYPE, exp.camera_topic: exp.camera_type}
    expect(dict(channels.values()) == want, f'channels {channels}, expected {want}')
    for name, _, text in m.schemas.values():
        expect(b'\nMSG: std_msgs/Header\n' in text, f'schema {name}: no std_msgs/Header section')
    stream = ((channels[x.channel_id][0], x.sequence, x.log_time, x.publish_time, x.data)
              for x in m.messages)
    check_messages(stream, exp, len(m.messages))
    body = m.metadata.get('rosbag2', {}).get('serialized_metadata')
    expect(body is not None, 'no rosbag2 Metadata record')
    check_bag_metadata(yaml.safe_load(body), exp, 'mcap', os.path.basename(path))
    return (f'{exp.summary()}; {len(m.chunks)} {compression or "uncompressed"} chunks, '
            f'indexes, CRCs and summary hold')


def check_messages(stream, exp, count):
    """stream: (topic, sequence, log time, publish time, CDR) in the output's order."""
    expected = list(exp.events())
    expect(count == len(expected), f'{count} messages, expected {len(expected)}')
    for (topic, seq, log_time, publish_time, data), (want_topic, index, t_ns, fields) in zip(
            stream, expected):
        what = f'{want_topic} #{index}'
        expect((topic, seq) == (want_topic, index), f'{what}: found {topic} #{seq} in its place')
        expect(log_time == t_ns and publish_time in (None, t_ns),
               f'{what}: log/publish time {log_time}/{publish_time}, expected {t_ns}')
        try:
            compare_fields(exp.decode(topic, data), fields, what, exp.field_names(topic))
        except cdr_reader.CdrError as e:
            raise Mismatch(f'{what}: {e}') from None


def check_bag_metadata(meta, exp, storage, file_name):
    """rosbag2's BagMetadata (version 8) of one storage file holding every message."""
    topics = [{'topic_metadata': {'name': t, 'type': ty, 'serialization_format': 'cdr',
                                  'offered_qos_profiles': '', 'type_description_hash': ''},
               'message_count': exp.counts[t]}
              for t, ty in ((exp.imu_topic, IMU_TYPE), (exp.camera_topic, exp.camera_type))]
    total = sum(exp.counts.values())
    want = {'version': 8, 'storage_identifier': storage,
            'duration': {'nanoseconds': exp.duration},
            'starting_time': {'nanoseconds_since_epoch': exp.start},
            'message_count': total, 'topics_with_message_count': topics,
            'compression_format': '', 'compression_mode': '',
            'relative_file_paths': [file_name],
            'files': [{'path': file_name,
                       'starting_time': {'nanoseconds_since_epoch': exp.start},
                       'duration': {'nanoseconds': exp.duration}, 'message_count': total}],
            'custom_data': None, 'ros_distro': ''}
    for key in want:
        expect(meta.get(key) == want[key], f'metadata {key}: {meta.get(key)!r}, expected '
               f'{want[key]!r}')
    expect(set(meta) == set(want), f'metadata keys {sorted(set(meta) ^ set(want))} differ')


def check_bag_folder(folder, exp, storage, extension, check_storage, *args):
    name = os.path.basename(os.path.normpath(folder)) + '_0' + extension
    with open(os.path.join(folder, 'metadata.yaml'), encoding='utf-8') as f:
        meta = yaml.safe_load(f)
    expect(list(meta) == ['rosbag2_bagfile_information'], 'metadata.yaml: no '
           'rosbag2_bagfile_information')
    check_bag_metadata(meta['rosbag2_bagfile_information'], exp, storage, name)
    return check_storage(os.path.join(folder, name), exp, *args) + '; metadata.yaml holds'


SQLITE_TABLES = {
    'schema': ['schema_version', 'ros_distro'],
    'metadata': ['id', 'metadata_version', 'metadata'],
    'topics': ['id', 'name', 'type', 'serialization_format', 'offered_qos_profiles',
               'type_description_hash'],
    'message_definitions': ['id', 'topic_type', 'encoding', 'encoded_message_definition',
                            'type_description_hash'],
    'messages': ['id', 'topic_id', 'timestamp', 'data'],
}


def check_sqlite(path, exp):
    db = sqlite3.connect(f'file:{path}?mode=ro', uri=True)
    try:
        expect(db.execute('PRAGMA integrity_check').fetchall() == [('ok',)], 'integrity check')
        tables = {name: [c[1] for c in db.execute(f'PRAGMA table_info({name})')]
                  for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        expect(tables == SQLITE_TABLES, f'tables {tables}')
        indexes = db.execute("SELECT name FROM sqlite_master WHERE type='index'").fetchall()
        expect(indexes == [('timestamp_idx',)], f'indexes {indexes}')
        expect(db.execute('SELECT * FROM schema').fetchall() == [(4, '')], 'schema row')
        topics = {i: (n, t) for i, n, t, fmt in db.execute(
            'SELECT id, name, type, serialization_format FROM topics') if fmt == 'cdr'}
        want = {(exp.imu_topic, IMU_TYPE), (exp.camera_topic, exp.camera_type)}
        expect(set(topics.values()) == want, f'topics {topics}')
        definitions = dict(db.execute('SELECT topic_type, encoding FROM message_definitions'))
        expect(definitions == {IMU_TYPE: 'ros2msg', exp.camera_type: 'ros2msg'},
               f'message definitions {definitions}')
        count = db.execute('SELECT COUNT(*) FROM messages').fetchone()[0]
        stream = ((topics[topic_id][0], None, t, None, data) for topic_id, t, data in
                  db.execute('SELECT topic_id, timestamp, data FROM messages ORDER BY id'))
        check_messages(_numbered(stream), exp, count)
        rows = db.execute('SELECT metadata_version, metadata FROM metadata').fetchall()
        expect(len(rows) == 1 and rows[0][0] == 8, f'metadata rows {[r[0] for r in rows]}')
        check_bag_metadata(yaml.safe_load(rows[0][1]), exp, 'sqlite3', os.path.basename(path))
    finally:
        db.close()
    return f'{exp.summary()}; rosbag2 sqlite schema 4'


def _numbered(stream):
    """Gives sqlite's messages, which have no sequence, their index on their topic."""
    seen = {}
    for topic, _, t, publish, data in stream:
        seen[topic] = seen.get(topic, -1) + 1
        yield topic, seen[topic], t, publish, data


# -------------------------------------------------------------------------------------------------
def check_output(name, out_dir, rec):
    path, kind, options = OUTPUTS[name]
    exp = Expected(rec, options.get('png_images', False))
    target = os.path.join(out_dir, path)
    if kind == 'ros1':
        return check_ros1(target, exp, options['compression'])
    if kind == 'mcap':
        return check_mcap(target, exp, options['compression'])
    if kind == 'mcap-bag':
        return check_bag_folder(target, exp, 'mcap', '.mcap', check_mcap, options['compression'])
    return check_bag_folder(target, exp, 'sqlite3', '.db3', check_sqlite)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('out_dir')
    parser.add_argument('--recording', help='the recording (default: the one write_bags.yaml '
                                            'names)')
    args = parser.parse_args(argv)
    with open(os.path.join(args.out_dir, MANIFEST), encoding='utf-8') as f:
        manifest = yaml.safe_load(f)
    rec = recording_io.load(args.recording or manifest['recording'])
    failed = 0
    for name in manifest['outputs']:
        try:
            print(f'{OUTPUTS[name][0]:18} ok: {check_output(name, args.out_dir, rec)}')
        except (Mismatch, mcap_reader.McapError) as e:
            failed += 1
            print(f'{OUTPUTS[name][0]:18} FAILED: {e}')
        except Exception as e:  # a reader's own complaint (rosbag, sqlite3, yaml, I/O)
            failed += 1
            print(f'{OUTPUTS[name][0]:18} FAILED: {type(e).__name__}: {e}')
    total = len(manifest['outputs'])
    print(f'read_back: {total - failed} of {total} outputs hold' if failed
          else f'read_back: all {total} outputs hold')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
