"""ROS 2 bags without ROS 2: single MCAP files and rosbag2's bag folders (metadata.yaml beside
one storage file, MCAP or sqlite3), as rosbag2 (Iron/Jazzy era) writes them.

metadata.yaml is rosbag2's BagMetadata at version 8: the last whose offered_qos_profiles is a
YAML string (version 9 made it a list), which rosbag2 still reads. The same YAML, without the
rosbag2_bagfile_information key, goes into the storage file as rosbag2 puts it there: an MCAP
Metadata record named "rosbag2" (key serialized_metadata), or a row of sqlite's metadata table."""
import os
import shutil
import sqlite3

from mcap_writer import McapWriter

METADATA_VERSION = 8
SQLITE_SCHEMA_VERSION = 4  # rosbag2's sqlite3 storage since Iron: tables schema and metadata
ROS_DISTRO = ''  # rosbag2 writes $ROS_DISTRO; there is none here
QOS_PROFILES = ''  # no offered QoS profiles recorded


def write_mcap(path, topics, messages, compression='zstd'):
    """A single MCAP file (profile ros2) of the messages, a ros2_msgs.serialize result."""
    with open(path, 'wb') as f:
        w = McapWriter(f, compression=compression, profile='ros2')
        channels = {}
        for topic in topics:
            schema = w.add_schema(topic.type, 'ros2msg', topic.definition.encode('utf-8'))
            # rosbag2's channel metadata: the QoS profiles and the type's hash (unknown here).
            channels[topic.name] = w.add_channel(
                topic.name, 'cdr', schema,
                {'offered_qos_profiles': QOS_PROFILES, 'topic_type_hash': ''})
        for m in messages:
            w.add_message(channels[m.topic.name], m.t_ns, m.data, m.t_ns, m.sequence)
        body = metadata_body('mcap', os.path.basename(path), topics, messages)
        w.add_metadata('rosbag2', {'serialized_metadata': body})
        w.finish()


def write_mcap_bag(folder, topics, messages, compression='zstd'):
    """A rosbag2 folder of storage mcap: metadata.yaml and <folder name>_0.mcap."""
    name = _fresh_folder(folder)
    write_mcap(os.path.join(folder, name), topics, messages, compression)
    _write_metadata_yaml(folder, metadata_body('mcap', name, topics, messages))


def write_sqlite_bag(folder, topics, messages):
    """A rosbag2 folder of storage sqlite3: metadata.yaml and <folder name>_0.db3, with the
    tables of rosbag2's sqlite storage at schema version 4."""
    name = _fresh_folder(folder, '.db3')
    body = metadata_body('sqlite3', name, topics, messages)
    db = sqlite3.connect(os.path.join(folder, name))
    try:
        _fill_sqlite(db, topics, messages, body)
        db.commit()
    finally:
        db.close()
    _write_metadata_yaml(folder, body)


def _fill_sqlite(db, topics, messages, metadata):
    # The statements of rosbag2's SqliteStorage::initialize(), in its order.
    db.execute('CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,'
               'ros_distro TEXT NOT NULL)')
    db.execute('CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,'
               'metadata TEXT NOT NULL)')
    db.execute('CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,'
               'serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL,'
               'type_description_hash TEXT NOT NULL)')
    db.execute('CREATE TABLE message_definitions(id INTEGER PRIMARY KEY,'
               'topic_type TEXT NOT NULL,encoding TEXT NOT NULL,'
               'encoded_message_definition TEXT NOT NULL,type_description_hash TEXT NOT NULL)')
    db.execute('CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,'
               'timestamp INTEGER NOT NULL, data BLOB NOT NULL)')
    db.execute('CREATE INDEX timestamp_idx ON messages (timestamp ASC)')
    db.execute('INSERT INTO schema (schema_version, ros_distro) VALUES (?, ?)',
               (SQLITE_SCHEMA_VERSION, ROS_DISTRO))
    topic_ids = {}
    for topic in topics:
        cursor = db.execute('INSERT INTO topics (name, type, serialization_format, '
                            'offered_qos_profiles, type_description_hash) VALUES (?, ?, ?, ?, ?)',
                            (topic.name, topic.type, 'cdr', QOS_PROFILES, ''))
        topic_ids[topic.name] = cursor.lastrowid
        db.execute('INSERT INTO message_definitions (topic_type, encoding, '
                   'encoded_message_definition, type_description_hash) VALUES (?, ?, ?, ?)',
                   (topic.type, 'ros2msg', topic.definition, ''))
    db.executemany('INSERT INTO messages (timestamp, topic_id, data) VALUES (?, ?, ?)',
                   ((m.t_ns, topic_ids[m.topic.name], m.data) for m in messages))
    # rosbag2 writes the metadata when it closes the file.
    db.execute('INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)',
               (METADATA_VERSION, metadata))


def metadata_body(storage, file_name, topics, messages):
    """rosbag2's BagMetadata as yaml-cpp writes it (keys in rosbag2's order, 2-space indents),
    for one storage file holding all the messages."""
    start = min((m.t_ns for m in messages), default=0)
    duration = max((m.t_ns for m in messages), default=0) - start
    lines = [f'version: {METADATA_VERSION}',
             f'storage_identifier: {storage}',
             'duration:', f'  nanoseconds: {duration}',
             'starting_time:', f'  nanoseconds_since_epoch: {start}',
             f'message_count: {len(messages)}',
             'topics_with_message_count:']
    for topic in topics:
        count = sum(1 for m in messages if m.topic.name == topic.name)
        lines += ['  - topic_metadata:',
                  f'      name: {topic.name}',
                  f'      type: {topic.type}',
                  '      serialization_format: cdr',
                  f'      offered_qos_profiles: "{QOS_PROFILES}"',
                  '      type_description_hash: ""',
                  f'    message_count: {count}']
    lines += ['compression_format: ""',  # the storage file is not compressed as a whole
              'compression_mode: ""',
              'relative_file_paths:', f'  - {file_name}',
              'files:',
              f'  - path: {file_name}',
              '    starting_time:', f'      nanoseconds_since_epoch: {start}',
              '    duration:', f'      nanoseconds: {duration}',
              f'    message_count: {len(messages)}',
              'custom_data: ~',
              f'ros_distro: "{ROS_DISTRO}"']
    return '\n'.join(lines)


def _write_metadata_yaml(folder, body):
    indented = '\n'.join('  ' + line for line in body.split('\n'))
    with open(os.path.join(folder, 'metadata.yaml'), 'w', encoding='utf-8') as f:
        f.write('rosbag2_bagfile_information:\n' + indented + '\n')


def _fresh_folder(folder, extension='.mcap'):
    """Empties (or makes) the bag folder; returns its storage file's name, as rosbag2 names
    the first file of a bag: <folder name>_0<extension>."""
    if os.path.isdir(folder):
        shutil.rmtree(folder)
    os.makedirs(folder)
    return os.path.basename(os.path.normpath(folder)) + '_0' + extension
