"""An MCAP writer (format version 0, the specification at mcap.dev/spec), written from the
specification for the tests: the C++ reader is checked against files it did not make.

The file it writes, like the MCAP library's own writer with its default options:

    magic, Header
    Chunk (Schema and Channel records before a channel's first message, Message records)
      Message Index records, one per channel in the chunk
    ... more chunks ...
    Metadata records (after the chunks)
    Data End (CRC32 of every byte before it, from the leading magic on)
    summary: Schema, Channel, Statistics, Chunk Index, Metadata Index groups
    Summary Offset records, one per group
    Footer (CRC32 from the summary's start to the footer's summary_offset_start field), magic
"""
import struct
import zlib
from enum import IntEnum

MAGIC = b'\x89MCAP0\r\n'
DEFAULT_CHUNK_SIZE = 1024 * 1024  # the MCAP library's default
LIBRARY = 'mirrorcal-tests'


class Op(IntEnum):
    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


# The specification's serializations: little-endian integers; a string, Bytes of a Schema, an
# Array or a Map is prefixed by its uint32 byte length.
def u16(v):
    return struct.pack('<H', v)


def u32(v):
    return struct.pack('<I', v)


def u64(v):
    return struct.pack('<Q', v)


def string(s):
    data = s.encode('utf-8')
    return u32(len(data)) + data


def prefixed(data):
    return u32(len(data)) + data


def string_map(mapping):
    return prefixed(b''.join(string(k) + string(v) for k, v in mapping.items()))


def u16_u64_map(mapping):
    return prefixed(b''.join(u16(k) + u64(v) for k, v in sorted(mapping.items())))


def record(op, *fields):
    """<opcode uint8><content length uint64><content>."""
    content = b''.join(fields)
    return struct.pack('<BQ', op, len(content)) + content


def compressor(name):
    """The chunk compressions of the specification's registry: "" (none), "zstd" (a Zstandard
    frame) and "lz4" (an LZ4 frame)."""
    if name == '':
        return lambda data: data
    if name == 'zstd':
        import zstandard
        # Level 1: the MCAP library's default (and fast, for the tests' tens of MB).
        return zstandard.ZstdCompressor(level=1).compress
    if name == 'lz4':
        import lz4.frame
        return lz4.frame.compress
    raise ValueError(f'unknown chunk compression {name!r}')


class _Output:
    """The file, its write position and the CRC32 of what was written since reset_crc()."""

    def __init__(self, f):
        self._f = f
        self.position = 0
        self.crc = 0

    def write(self, data):
        self._f.write(data)
        self.position += len(data)
        self.crc = zlib.crc32(data, self.crc)

    def reset_crc(self):
        self.crc = 0


class _Chunk:
    """The records of the chunk being filled, uncompressed, and its message index."""

    def __init__(self):
        self.parts = []
        self.size = 0
        self.start_time = None
        self.end_time = None
        self.index = {}  # channel id -> [(log_time, offset in the uncompressed records)]

    def add(self, data):
        self.parts.append(data)
        self.size += len(data)

    def add_message(self, channel_id, log_time, data):
        self.index.setdefault(channel_id, []).append((log_time, self.size))
        self.add(data)
        self.start_time = log_time if self.start_time is None else min(self.start_time, log_time)
        self.end_time = log_time if self.end_time is None else max(self.end_time, log_time)


class McapWriter:
    """Writes an indexed, chunked MCAP file to the binary stream f.

        w = McapWriter(f, compression='zstd', profile='ros2')
        schema = w.add_schema('sensor_msgs/msg/Imu', 'ros2msg', text.encode())
        channel = w.add_channel('/imu0', 'cdr', schema, {'offered_qos_profiles': ''})
        w.add_message(channel, log_time_ns, cdr_bytes, publish_time_ns, sequence)
        w.finish()
    """

    def __init__(self, f, compression='zstd', chunk_size=DEFAULT_CHUNK_SIZE, profile='',
                 library=LIBRARY):
        self._out = _Output(f)
        self._compression = compression
        self._compress = compressor(compression)
        self._chunk_size = chunk_size
        self._chunk = _Chunk()
        self._schemas = {}       # id -> Schema record
        self._channels = {}      # id -> (Channel record, schema id)
        self._written = set()    # ('schema' or 'channel', id) already in the data section
        self._message_counts = {}
        self._start_time = None
        self._end_time = None
        self._chunk_indexes = []
        self._metadata_indexes = []
        self._chunk_count = 0
        self._out.write(MAGIC)
        self._out.write(record(Op.HEADER, string(profile), string(library)))

    def add_schema(self, name, encoding, data):
        schema_id = len(self._schemas) + 1  # 0 means "no schema"
        self._schemas[schema_id] = record(Op.SCHEMA, u16(schema_id), string(name),
                                          string(encoding), prefixed(data))
        return schema_id

    def add_channel(self, topic, message_encoding, schema_id, metadata):
        channel_id = len(self._channels) + 1
        self._channels[channel_id] = (
            record(Op.CHANNEL, u16(channel_id), u16(schema_id), string(topic),
                   string(message_encoding), string_map(metadata)),
            schema_id)
        self._message_counts[channel_id] = 0
        return channel_id

    def add_message(self, channel_id, log_time, data, publish_time=None, sequence=0):
        message = record(Op.MESSAGE, u16(channel_id), u32(sequence), u64(log_time),
                         u64(log_time if publish_time is None else publish_time), data)
        # Like the MCAP library: a message that would overflow a chunk starts the next one.
        if self._chunk.size and self._chunk.size + len(message) >= self._chunk_size:
            self._close_chunk()
        self._introduce(channel_id)
        self._chunk.add_message(channel_id, log_time, message)
        self._message_counts[channel_id] += 1
        self._start_time = log_time if self._start_time is None else min(self._start_time,
                                                                           log_time)
        self._end_time = log_time if self._end_time is None else max(self._end_time, log_time)
        if self._chunk.size >= self._chunk_size:
            self._close_chunk()

    def add_metadata(self, name, mapping):
        """A Metadata record in the data section (outside any chunk), indexed in the summary."""
        self._close_chunk()
        data = record(Op.METADATA, string(name), string_map(mapping))
        self._metadata_indexes.append(
            record(Op.METADATA_INDEX, u64(self._out.position), u64(len(data)), string(name)))
        self._out.write(data)

    def finish(self):
        self._close_chunk()
        self._out.write(record(Op.DATA_END, u32(self._out.crc)))
        summary_start = self._out.position
        groups = [(Op.SCHEMA, list(self._schemas.values())),
                  (Op.CHANNEL, [channel for channel, _ in self._channels.values()]),
                  (Op.STATISTICS, [self._statistics()]),
                  (Op.CHUNK_INDEX, self._chunk_indexes),
                  (Op.METADATA_INDEX, self._metadata_indexes)]
        self._out.reset_crc()
        offsets = []
        for op, records in groups:
            if records:
                start = self._out.position
                for r in records:
                    self._out.write(r)
                offsets.append(record(Op.SUMMARY_OFFSET, struct.pack('<B', op), u64(start),
                                      u64(self._out.position - start)))
        summary_offset_start = self._out.position
        for r in offsets:
            self._out.write(r)
        # The footer's CRC covers the summary, the summary offsets and the footer up to its
        # summary_offset_start field: write those bytes first, then the CRC.
        self._out.write(struct.pack('<BQ', Op.FOOTER, 20) + u64(summary_start)
                        + u64(summary_offset_start))
        self._out.write(u32(self._out.crc))
        self._out.write(MAGIC)

    def _introduce(self, channel_id):
        """Puts the channel's Schema and Channel records in the current chunk before its first
        message (as the MCAP library does), once in the file."""
        channel, schema_id = self._channels[channel_id]
        if schema_id and ('schema', schema_id) not in self._written:
            self._chunk.add(self._schemas[schema_id])
            self._written.add(('schema', schema_id))
        if ('channel', channel_id) not in self._written:
            self._chunk.add(channel)
            self._written.add(('channel', channel_id))

    def _close_chunk(self):
        chunk = self._chunk
        if not chunk.parts:
            return
        self._chunk = _Chunk()
        records = b''.join(chunk.parts)
        compressed = self._compress(records)
        start = self._out.position
        self._out.write(record(Op.CHUNK, u64(chunk.start_time or 0), u64(chunk.end_time or 0),
                               u64(len(records)), u32(zlib.crc32(records)),
                               string(self._compression), u64(len(compressed)), compressed))
        chunk_length = self._out.position - start
        index_offsets = {}
        for channel_id in sorted(chunk.index):
            index_offsets[channel_id] = self._out.position
            entries = b''.join(u64(t) + u64(offset) for t, offset in chunk.index[channel_id])
            self._out.write(record(Op.MESSAGE_INDEX, u16(channel_id), prefixed(entries)))
        self._chunk_indexes.append(record(
            Op.CHUNK_INDEX, u64(chunk.start_time or 0), u64(chunk.end_time or 0), u64(start),
            u64(chunk_length), u16_u64_map(index_offsets),
            u64(self._out.position - start - chunk_length), string(self._compression),
            u64(len(compressed)), u64(len(records))))
        self._chunk_count += 1

    def _statistics(self):
        return record(Op.STATISTICS, u64(sum(self._message_counts.values())),
                      u16(len(self._schemas)), u32(len(self._channels)),
                      u32(0),  # attachments
                      u32(len(self._metadata_indexes)), u32(self._chunk_count),
                      u64(self._start_time or 0), u64(self._end_time or 0),
                      u16_u64_map(self._message_counts))
