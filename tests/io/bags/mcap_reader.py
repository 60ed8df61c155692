"""A strict MCAP reader for the tests, written from the specification (mcap.dev/spec, format
version 0) apart from mcap_writer.py: it reads the whole file record by record and checks what
the specification lets a reader check, raising McapError at the first thing that is wrong:

- the magic at both ends, the Header first, the Footer last, Data End closing the data section;
- each chunk: its compression, sizes, CRC32 of the uncompressed records, the time range of its
  messages, and only Schema, Channel and Message records inside;
- the Message Index records after each chunk: one per channel in it, each entry at a Message of
  that channel and log time, every message indexed;
- schemas and channels: defined before use, every repetition identical;
- the data section's CRC32 (Data End) and the summary's (Footer);
- the summary: records grouped by opcode, its Schema and Channel records the data section's,
  Statistics, Chunk Index and Metadata Index records matching what the data section holds,
  and one Summary Offset record per group, pointing at it.
"""
import struct
import zlib
from dataclasses import dataclass, field

MAGIC = b'\x89MCAP0\r\n'
SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = 0x03, 0x04, 0x05, 0x06, 0x07, 0x08
HEADER, FOOTER, ATTACHMENT, ATTACHMENT_INDEX, STATISTICS = 0x01, 0x02, 0x09, 0x0A, 0x0B
METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 0x0C, 0x0D, 0x0E, 0x0F
DATA_OPS = {SCHEMA, CHANNEL, MESSAGE, ATTACHMENT, CHUNK, MESSAGE_INDEX, METADATA, DATA_END}
SUMMARY_OPS = {SCHEMA, CHANNEL, CHUNK_INDEX, ATTACHMENT_INDEX, METADATA_INDEX, STATISTICS}


class McapError(Exception):
    pass


def check(condition, message):
    if not condition:
        raise McapError(message)


class Fields:
    """Reads one record's fields in order (the specification's serializations)."""

    def __init__(self, data, what):
        self.data = data
        self.pos = 0
        self.what = what

    def take(self, n):
        check(self.pos + n <= len(self.data), f'{self.what}: truncated field')
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def int(self, fmt):
        return struct.unpack(fmt, self.take(struct.calcsize(fmt)))[0]

    def u8(self):
        return self.int('<B')

    def u16(self):
        return self.int('<H')

    def u32(self):
        return self.int('<I')

    def u64(self):
        return self.int('<Q')

    def string(self):
        return bytes(self.take(self.u32())).decode('utf-8')

    def u32_bytes(self):
        return bytes(self.take(self.u32()))

    def u64_bytes(self):
        return self.take(self.u64())

    def string_map(self):
        inner = Fields(self.take(self.u32()), self.what + ' map')
        out = {}
        while not inner.at_end():
            key = inner.string()
            check(key not in out, f'{self.what}: key {key!r} twice')
            out[key] = inner.string()
        return out

    def u16_u64_map(self):
        inner = Fields(self.take(self.u32()), self.what + ' map')
        out = {}
        while not inner.at_end():
            key = inner.u16()
            check(key not in out, f'{self.what}: key {key} twice')
            out[key] = inner.u64()
        return out

    def at_end(self):
        return self.pos == len(self.data)


def records(data, start, end, what):
    """(offset, opcode, content) of the records in data[start:end]."""
    pos = start
    while pos < end:
        check(pos + 9 <= end, f'{what}: record header runs past the end at {pos}')
        op, length = struct.unpack_from('<BQ', data, pos)
        check(op != 0, f'{what}: opcode 0 at {pos}')
        check(pos + 9 + length <= end, f'{what}: record at {pos} runs past the end')
        yield pos, op, data[pos + 9:pos + 9 + length]
        pos += 9 + length


@dataclass
class Message:
    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


@dataclass
class McapFile:
    profile: str = ''
    library: str = ''
    schemas: dict = field(default_factory=dict)   # id -> (name, encoding, data)
    channels: dict = field(default_factory=dict)  # id -> (schema id, topic, encoding, metadata)
    messages: list = field(default_factory=list)  # Message, in file order
    metadata: dict = field(default_factory=dict)  # name -> {key: value}
    metadata_records: list = field(default_factory=list)  # (offset, length, name)
    chunks: list = field(default_factory=list)    # dicts of what a Chunk Index should say
    compressions: set = field(default_factory=set)
    summary_groups: list = field(default_factory=list)  # opcodes, in the summary's order
    zero_crcs: list = field(default_factory=list)  # the CRCs a writer left out (0), by name


def read(path):
    with open(path, 'rb') as f:
        data = f.read()
    return parse(memoryview(data))


def parse(data):
    check(len(data) >= 2 * len(MAGIC) + 9 + 29, 'too short for an MCAP file')
    check(bytes(data[:8]) == MAGIC, 'no leading magic')
    check(bytes(data[-8:]) == MAGIC, 'no trailing magic')
    mcap = McapFile()
    footer_at = len(data) - 8 - 29  # Footer: opcode, length, 8 + 8 + 4 bytes
    check(data[footer_at] == FOOTER and struct.unpack_from('<Q', data, footer_at + 1)[0] == 20,
          'no Footer record before the trailing magic')
    summary_start, summary_offset_start, summary_crc = struct.unpack_from('<QQI', data,
                                                                          footer_at + 9)
    data_end = _read_data_section(data, footer_at, mcap)
    summary_end = summary_offset_start or footer_at
    check(summary_start == (data_end if summary_end > data_end else 0),
          f'summary_start {summary_start}: the summary starts at {data_end}')
    if summary_crc:
        crc = zlib.crc32(data[data_end:footer_at + 9 + 16])
        check(crc == summary_crc, f'summary CRC {summary_crc:#x}, computed {crc:#x}')
    else:
        mcap.zero_crcs.append('summary')
    groups = _read_summary(data, data_end, summary_end, mcap)
    if summary_offset_start:
        _check_summary_offsets(data, summary_offset_start, footer_at, groups)
    return mcap


def _read_data_section(data, footer_at, mcap):
    """Reads the Header and the data section; returns the offset where the summary starts."""
    it = records(data, 8, footer_at, 'data section')
    pos, op, content = next(it)
    check(op == HEADER, 'the first record is not a Header')
    header = Fields(content, 'Header')
    mcap.profile, mcap.library = header.string(), header.string()
    pending_chunk = None  # the last chunk, until its message indexes are read
    for pos, op, content in it:
        check(op in DATA_OPS, f'opcode {op:#x} in the data section at {pos}')
        if op != MESSAGE_INDEX and pending_chunk:
            _finish_message_indexes(pending_chunk)
            pending_chunk = None
        if op == MESSAGE_INDEX:
            check(pending_chunk is not None, f'Message Index at {pos} not after a chunk')
            _read_message_index(content, pos, pending_chunk)
        elif op == CHUNK:
            pending_chunk = _read_chunk(content, pos, mcap)
        elif op in (SCHEMA, CHANNEL, MESSAGE):
            _read_definition_or_message(op, content, mcap, pos)
        elif op == METADATA:
            f = Fields(content, 'Metadata')
            name = f.string()
            mcap.metadata[name] = f.string_map()
            mcap.metadata_records.append((pos, 9 + len(content), name))
        elif op == DATA_END:
            crc = Fields(content, 'Data End').u32()
            computed = zlib.crc32(data[:pos])
            check(crc in (0, computed), f'data section CRC {crc:#x}, computed {computed:#x}')
            if not crc:
                mcap.zero_crcs.append('data section')
            return pos + 9 + len(content)
        # An Attachment is allowed but these files have none: nothing to check it against.
    raise McapError('no Data End record')


def _read_chunk(content, pos, mcap):
    f = Fields(content, f'Chunk at {pos}')
    start_time, end_time, size, crc = f.u64(), f.u64(), f.u64(), f.u32()
    compression = f.string()
    compressed = bytes(f.u64_bytes())
    records_data = _decompress(compression, compressed, size)
    check(len(records_data) == size, f'Chunk at {pos}: {len(records_data)} bytes, says {size}')
    check(crc == 0 or zlib.crc32(records_data) == crc, f'Chunk at {pos}: CRC mismatch')
    if not crc:
        mcap.zero_crcs.append(f'chunk at {pos}')
    mcap.compressions.add(compression)
    first_message = len(mcap.messages)
    offsets = {}  # offset in the records -> Message
    for at, op, inner in records(memoryview(records_data), 0, len(records_data), 'chunk'):
        check(op in (SCHEMA, CHANNEL, MESSAGE), f'opcode {op:#x} inside the chunk at {pos}')
        message = _read_definition_or_message(op, inner, mcap, pos)
        if message:
            offsets[at] = message
    times = [m.log_time for m in mcap.messages[first_message:]]
    check((start_time, end_time) == ((min(times), max(times)) if times else (0, 0)),
          f'Chunk at {pos}: time range ({start_time}, {end_time}) is not its messages\'')
    chunk = dict(start_time=start_time, end_time=end_time, offset=pos, length=9 + len(content),
                 compression=compression, compressed_size=len(compressed),
                 uncompressed_size=size, index_offsets={}, index_length=0,
                 unindexed=dict(offsets))
    mcap.chunks.append(chunk)
    return chunk


def _decompress(compression, data, size):
    if compression == '':
        return data
    if compression == 'zstd':
        import zstandard
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.decompress(data)
    raise McapError(f'unknown chunk compression {compression!r}')


def _read_definition_or_message(op, content, mcap, pos):
    """Schema and Channel records define (identically each time); a Message is appended to
    mcap.messages and returned."""
    f = Fields(content, f'record at {pos}')
    if op == SCHEMA:
        schema_id = f.u16()
        check(schema_id != 0, f'Schema of id 0 at {pos}')
        schema = (f.string(), f.string(), f.u32_bytes())
        check(mcap.schemas.setdefault(schema_id, schema) == schema, f'Schema {schema_id} differs')
    elif op == CHANNEL:
        channel_id, schema_id = f.u16(), f.u16()
        check(schema_id == 0 or schema_id in mcap.schemas,
              f'Channel {channel_id} before its Schema {schema_id}')
        channel = (schema_id, f.string(), f.string(), f.string_map())
        check(mcap.channels.setdefault(channel_id, channel) == channel,
              f'Channel {channel_id} differs')
    else:
        channel_id = f.u16()
        check(channel_id in mcap.channels, f'Message of channel {channel_id} before its Channel')
        message = Message(channel_id, f.u32(), f.u64(), f.u64(), bytes(f.data[f.pos:]))
        mcap.messages.append(message)
        return message
    check(f.at_end(), f'record at {pos}: bytes past its fields')  # none extended here
    return None


def _read_message_index(content, pos, chunk):
    f = Fields(content, f'Message Index at {pos}')
    channel_id = f.u16()
    check(channel_id not in chunk['index_offsets'], f'second Message Index of {channel_id}')
    chunk['index_offsets'][channel_id] = pos
    chunk['index_length'] += 9 + len(content)
    entries = Fields(f.take(f.u32()), 'Message Index entries')
    while not entries.at_end():
        log_time, offset = entries.u64(), entries.u64()
        message = chunk['unindexed'].pop(offset, None)
        check(message is not None and message.channel_id == channel_id
              and message.log_time == log_time,
              f'Message Index at {pos}: no message of channel {channel_id} at {log_time} '
              f'at offset {offset}')


def _finish_message_indexes(chunk):
    check(not chunk['unindexed'], f"Chunk at {chunk['offset']}: {len(chunk['unindexed'])} "
          'messages no Message Index lists')
    del chunk['unindexed']


def _read_summary(data, start, end, mcap):
    """Checks the summary records in data[start:end] against the data section; returns the
    groups as {opcode: (start, length)}."""
    groups = {}
    summary_schemas, summary_channels, chunk_indexes, metadata_indexes = {}, {}, [], []
    statistics = None
    last_op = None
    for pos, op, content in records(data, start, end, 'summary'):
        check(op in SUMMARY_OPS, f'opcode {op:#x} in the summary at {pos}')
        if op != last_op:
            check(op not in groups, f'summary records of opcode {op:#x} not grouped')
            groups[op] = (pos, 0)
            mcap.summary_groups.append(op)
            last_op = op
        groups[op] = (groups[op][0], pos + 9 + len(content) - groups[op][0])
        f = Fields(content, f'summary record at {pos}')
        if op == SCHEMA:
            schema_id = f.u16()
            summary_schemas[schema_id] = (f.string(), f.string(), f.u32_bytes())
        elif op == CHANNEL:
            channel_id, schema_id = f.u16(), f.u16()
            summary_channels[channel_id] = (schema_id, f.string(), f.string(), f.string_map())
        elif op == STATISTICS:
            check(statistics is None, 'two Statistics records')
            statistics = (f.u64(), f.u16(), f.u32(), f.u32(), f.u32(), f.u32(), f.u64(),
                          f.u64(), f.u16_u64_map())
        elif op == CHUNK_INDEX:
            chunk_indexes.append(dict(
                start_time=f.u64(), end_time=f.u64(), offset=f.u64(), length=f.u64(),
                index_offsets=f.u16_u64_map(), index_length=f.u64(), compression=f.string(),
                compressed_size=f.u64(), uncompressed_size=f.u64()))
        elif op == METADATA_INDEX:
            metadata_indexes.append((f.u64(), f.u64(), f.string()))
    # The summary repeats every Schema and Channel of the data section; the MCAP library also
    # lists there those of channels that had no message (and so never reached a chunk).
    # Statistics may count the schemas and channels of the data section or all (the MCAP
    # library counts those that reached the data section).
    counts_in_data = len(mcap.schemas), len(mcap.channels)
    _check_repeated(summary_schemas, mcap.schemas, 'Schema')
    _check_repeated(summary_channels, mcap.channels, 'Channel')
    check(chunk_indexes == mcap.chunks, 'Chunk Index records do not match the chunks')
    check(metadata_indexes == mcap.metadata_records,
          'Metadata Index records do not match the Metadata records')
    if statistics:
        _check_statistics(statistics, mcap, counts_in_data)
    return groups


def _check_repeated(in_summary, in_data, what):
    for key, value in in_data.items():
        check(in_summary.get(key) == value, f'{what} {key} of the data section is not in the '
              'summary as it is there')
    in_data.update(in_summary)


def _check_statistics(statistics, mcap, counts_in_data):
    message_count, schema_count, channel_count, *rest = statistics
    times = [m.log_time for m in mcap.messages]
    per_channel = {}
    for m in mcap.messages:
        per_channel[m.channel_id] = per_channel.get(m.channel_id, 0) + 1
    expected = [0, len(mcap.metadata_records), len(mcap.chunks), min(times, default=0),
                max(times, default=0), per_channel]
    check(message_count == len(mcap.messages) and rest == expected
          and schema_count in (counts_in_data[0], len(mcap.schemas))
          and channel_count in (counts_in_data[1], len(mcap.channels)),
          f'Statistics {statistics[:8]} do not match the file')


def _check_summary_offsets(data, start, end, groups):
    seen = {}
    for pos, op, content in records(data, start, end, 'summary offsets'):
        check(op == SUMMARY_OFFSET, f'opcode {op:#x} among the Summary Offsets')
        f = Fields(content, 'Summary Offset')
        group_op, group_start, group_length = f.u8(), f.u64(), f.u64()
        check(group_op not in seen, f'two Summary Offsets for opcode {group_op:#x}')
        seen[group_op] = (group_start, group_length)
    check(seen == groups, f'Summary Offsets {seen} do not point at the groups {groups}')
