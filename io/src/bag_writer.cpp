// A recording's streams as a ROS 2 bag folder (bags.hpp's BagWriter), as rosbag2 (its metadata
// version 8, Iron and later) writes one: metadata.yaml beside one MCAP file (mcap.dev/spec,
// version 0, profile ros2) of CDR messages in zstd chunks, each followed by its message indexes,
// the same metadata in a Metadata record named "rosbag2", then a summary (schemas, channels,
// statistics, chunk and metadata indexes, summary offsets) and the footer, with the data
// section's and the summary's CRC32.
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <string_view>
#include <utility>
#include <vector>

#include "bag_containers.hpp"
#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/files.hpp"
#include "mirrorcal/io/version.hpp"

namespace mirrorcal::io {

using namespace bag;  // MCAP's magic and opcodes (bag_containers.hpp)

namespace {

// A chunk is closed once its records pass this many bytes: what a reader holds at a time.
constexpr std::size_t kChunkBytes = 4u << 20;
constexpr int kZstdLevel = 3;

// Little-endian fields appended to a byte buffer: MCAP's records and ROS 2's CDR.
class Bytes {
 public:
  template <typename T>
  void put(T v) {
    static_assert(std::is_arithmetic_v<T>, "a primitive");
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);  // the host is little-endian
    data.insert(data.end(), p, p + sizeof(T));
  }
  void append(const void* p, std::size_t n) {
    const auto* b = static_cast<const std::uint8_t*>(p);
    data.insert(data.end(), b, b + n);
  }
  void string(std::string_view s) {  // MCAP's: a u32 length, no NUL
    put(std::uint32_t(s.size()));
    append(s.data(), s.size());
  }
  // A map<string, string>: its entries' byte length, then each key and value.
  void string_map(std::initializer_list<std::pair<std::string_view, std::string_view>> entries) {
    Bytes m;
    for (const auto& [key, value] : entries) {
      m.string(key);
      m.string(value);
    }
    put(std::uint32_t(m.data.size()));
    append(m.data.data(), m.data.size());
  }
  // A record: its opcode, its content's length, its content.
  void record(McapOp op, const Bytes& content) {
    put(std::uint8_t(op));
    put(std::uint64_t(content.data.size()));
    append(content.data.data(), content.data.size());
  }
  std::vector<std::uint8_t> data;
};

// A CDR message (little-endian, encapsulation 00 01 00 00): each primitive aligned to its size
// from the end of the encapsulation header.
class Cdr {
 public:
  Cdr() { out_.append("\x00\x01\x00\x00", 4); }
  template <typename T>
  void put(T v) {
    while ((out_.data.size() - 4) % sizeof(T) != 0) out_.put(std::uint8_t(0));
    out_.put(v);
  }
  void string(std::string_view s) {  // its length counts the closing NUL
    put(std::uint32_t(s.size() + 1));
    out_.append(s.data(), s.size());
    out_.put(std::uint8_t(0));
  }
  void bytes(const std::uint8_t* p, std::size_t n) {
    put(std::uint32_t(n));
    out_.append(p, n);
  }
  void header(std::int64_t stamp_ns, std::string_view frame_id) {
    // builtin_interfaces/Time: the seconds floor, the nanoseconds in [0, 1e9).
    std::int64_t sec = stamp_ns / 1000000000, nsec = stamp_ns % 1000000000;
    if (nsec < 0) {
      nsec += 1000000000;
      --sec;
    }
    put(std::int32_t(sec));
    put(std::uint32_t(nsec));
    string(frame_id);
  }
  const std::vector<std::uint8_t>& data() const { return out_.data; }

 private:
  Bytes out_;
};

// The messages' definitions as rosbag2 stores them (ros2msg: the type's fields, then each type
// it uses after a line of '=' and "MSG: name").
constexpr const char* kSeparator =
    "================================================================================\n";
std::string header_definitions() {
  return std::string(kSeparator) + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\n" +
         "string frame_id\n" + kSeparator +
         "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
}
std::string imu_definition() {
  return "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
         "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
         "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
         "float64[9] linear_acceleration_covariance\n" +
         header_definitions() + kSeparator +
         "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n" +
         kSeparator + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
}
std::string image_definition() {
  return "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
         "uint8 is_bigendian\nuint32 step\nuint8[] data\n" +
         header_definitions();
}

struct ChannelInfo {
  std::uint16_t id;
  std::string topic, type, frame_id;
  std::uint64_t messages = 0;
};

}  // namespace

struct BagWriter::Impl {
  io::OutputSet out;
  std::FILE* file = nullptr;
  std::string folder, file_name, path, error;
  std::uint64_t offset = 0;  // bytes written to the file
  std::uint32_t data_crc = 0;
  ChannelInfo imu{1, "", "sensor_msgs/msg/Imu", "imu0"};
  ChannelInfo camera{2, "", "sensor_msgs/msg/Image", "cam0"};
  // The open chunk: its records, each channel's (log time, offset) entries, its time range.
  Bytes chunk;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> index;
  std::uint64_t chunk_start = 0, chunk_end = 0;
  Bytes chunk_indexes;  // the summary's Chunk Index records, as the chunks close
  std::uint32_t chunks = 0;
  std::uint64_t first_time = 0, last_time = 0, messages = 0;
  std::vector<std::uint8_t> compressed;

  bool write(const std::vector<std::uint8_t>& bytes, std::uint32_t* crc) {
    if (file == nullptr) return false;
    if (std::fwrite(bytes.data(), 1, bytes.size(), file) != bytes.size())
      return fail("cannot write");
    if (crc != nullptr) *crc = std::uint32_t(crc32(*crc, bytes.data(), uInt(bytes.size())));
    offset += bytes.size();
    return true;
  }
  bool fail(const std::string& what) {
    if (error.empty()) error = path + ": " + what + ": " + std::strerror(errno);
    file = nullptr;
    return false;
  }
  Bytes schema(const ChannelInfo& c) const {
    Bytes s;
    s.put(c.id);  // one schema per channel, of the channel's id
    s.string(c.type);
    s.string("ros2msg");
    s.string(c.id == imu.id ? imu_definition() : image_definition());
    return s;
  }
  Bytes channel(const ChannelInfo& c) const {
    Bytes s;
    s.put(c.id);
    s.put(c.id);  // its schema's
    s.string(c.topic);
    s.string("cdr");
    // rosbag2's: the publishers' QoS profiles and the type's hash, unknown here.
    s.string_map({{"offered_qos_profiles", ""}, {"topic_type_hash", ""}});
    return s;
  }
  bool add(ChannelInfo& c, std::int64_t t_ns, const std::vector<std::uint8_t>& cdr) {
    if (file == nullptr) return false;
    const auto t = static_cast<std::uint64_t>(std::max<std::int64_t>(t_ns, 0));
    if (index.empty()) chunk_start = chunk_end = t;
    chunk_start = std::min(chunk_start, t);
    chunk_end = std::max(chunk_end, t);
    first_time = messages == 0 ? t : std::min(first_time, t);
    last_time = std::max(last_time, t);
    index[c.id].emplace_back(t, chunk.data.size());
    Bytes m;
    m.put(c.id);
    m.put(std::uint32_t(c.messages));  // sequence
    m.put(t);                          // log time
    m.put(t);                          // publish time
    m.append(cdr.data(), cdr.size());
    chunk.record(kMcapMessage, m);
    ++c.messages;
    ++messages;
    return chunk.data.size() < kChunkBytes || close_chunk();
  }
  // The open chunk, compressed, then its message indexes; its Chunk Index kept for the summary.
  bool close_chunk() {
    if (index.empty()) return true;
    const std::uint64_t start = offset;
    compressed.resize(ZSTD_compressBound(chunk.data.size()));
    const std::size_t n = ZSTD_compress(compressed.data(), compressed.size(), chunk.data.data(),
                                        chunk.data.size(), kZstdLevel);
    if (ZSTD_isError(n)) {
      error = path + ": zstd: " + ZSTD_getErrorName(n);
      file = nullptr;
      return false;
    }
    Bytes c;
    c.put(chunk_start);
    c.put(chunk_end);
    c.put(std::uint64_t(chunk.data.size()));
    c.put(std::uint32_t(crc32(0, chunk.data.data(), uInt(chunk.data.size()))));
    c.string("zstd");
    c.put(std::uint64_t(n));
    c.append(compressed.data(), n);
    Bytes record;
    record.record(kMcapChunk, c);
    if (!write(record.data, &data_crc)) return false;
    const std::uint64_t chunk_length = offset - start;
    Bytes offsets;  // the Chunk Index's map: channel -> its Message Index's offset
    for (const auto& [id, entries] : index) {
      Bytes mi, list;
      for (const auto& [t, at] : entries) {
        list.put(t);
        list.put(at);
      }
      mi.put(id);
      mi.put(std::uint32_t(list.data.size()));
      mi.append(list.data.data(), list.data.size());
      offsets.put(id);
      offsets.put(offset);
      Bytes r;
      r.record(kMcapMessageIndex, mi);
      if (!write(r.data, &data_crc)) return false;
    }
    Bytes ci;
    ci.put(chunk_start);
    ci.put(chunk_end);
    ci.put(start);
    ci.put(chunk_length);
    ci.put(std::uint32_t(offsets.data.size()));
    ci.append(offsets.data.data(), offsets.data.size());
    ci.put(offset - start - chunk_length);  // the message indexes' length
    ci.string("zstd");
    ci.put(std::uint64_t(n));
    ci.put(std::uint64_t(chunk.data.size()));
    chunk_indexes.record(kMcapChunkIndex, ci);
    ++chunks;
    chunk.data.clear();
    index.clear();
    return true;
  }
  // Data End, the summary, its offsets and the footer, the magic.
  bool finish() {
    if (!close_chunk()) return false;
    Bytes metadata, content;
    content.string("rosbag2");
    content.string_map({{"serialized_metadata", bag_metadata()}});
    metadata.record(kMcapMetadata, content);
    const std::uint64_t metadata_at = offset;
    if (!write(metadata.data, &data_crc)) return false;
    Bytes metadata_index, mi;
    mi.put(metadata_at);
    mi.put(std::uint64_t(metadata.data.size()));
    mi.string("rosbag2");
    metadata_index.record(kMcapMetadataIndex, mi);
    Bytes end, end_content;
    end_content.put(data_crc);
    end.record(kMcapDataEnd, end_content);
    if (!write(end.data, nullptr)) return false;
    const std::uint64_t summary_start = offset;
    std::uint32_t summary_crc = 0;
    Bytes schemas, channels, statistics;
    for (const ChannelInfo* c : {&imu, &camera}) {
      schemas.record(kMcapSchema, schema(*c));
      channels.record(kMcapChannel, channel(*c));
    }
    Bytes st, counts;
    st.put(messages);
    st.put(std::uint16_t(2));  // schemas
    st.put(std::uint32_t(2));  // channels
    st.put(std::uint32_t(0));  // attachments
    st.put(std::uint32_t(1));  // metadata: rosbag2's
    st.put(chunks);
    st.put(first_time);
    st.put(last_time);
    for (const ChannelInfo* c : {&imu, &camera}) {
      counts.put(c->id);
      counts.put(c->messages);
    }
    st.put(std::uint32_t(counts.data.size()));
    st.append(counts.data.data(), counts.data.size());
    statistics.record(kMcapStatistics, st);
    Bytes offsets;
    for (const auto& [op, group] : {std::pair<McapOp, const Bytes*>{kMcapSchema, &schemas},
                                    {kMcapChannel, &channels},
                                    {kMcapStatistics, &statistics},
                                    {kMcapChunkIndex, &chunk_indexes},
                                    {kMcapMetadataIndex, &metadata_index}}) {
      if (group->data.empty()) continue;
      Bytes so;
      so.put(std::uint8_t(op));
      so.put(offset);
      so.put(std::uint64_t(group->data.size()));
      offsets.record(kMcapSummaryOffset, so);
      if (!write(group->data, &summary_crc)) return false;
    }
    const std::uint64_t summary_offset_start = offset;
    if (!write(offsets.data, &summary_crc)) return false;
    Bytes footer;
    footer.put(std::uint8_t(kMcapFooter));
    footer.put(std::uint64_t(20));
    footer.put(summary_start);
    footer.put(summary_offset_start);
    summary_crc = std::uint32_t(crc32(summary_crc, footer.data.data(), uInt(footer.data.size())));
    footer.put(summary_crc);
    footer.append(kMcapMagic, sizeof kMcapMagic);
    return write(footer.data, nullptr);
  }
  // rosbag2's BagMetadata (version 8) of the bag, as yaml-cpp writes it, indented by indent.
  std::string bag_metadata(const std::string& indent = "") const {
    const std::string duration = std::to_string(messages ? last_time - first_time : 0);
    const std::string start = std::to_string(first_time);
    std::string y = "version: 8\nstorage_identifier: mcap\nduration:\n  nanoseconds: " + duration +
                    "\nstarting_time:\n  nanoseconds_since_epoch: " + start +
                    "\nmessage_count: " + std::to_string(messages) +
                    "\ntopics_with_message_count:\n";
    for (const ChannelInfo* c : {&imu, &camera})
      y += "  - topic_metadata:\n      name: " + c->topic + "\n      type: " + c->type +
           "\n      serialization_format: cdr\n      offered_qos_profiles: \"\"\n"
           "      type_description_hash: \"\"\n    message_count: " +
           std::to_string(c->messages) + "\n";
    y += "compression_format: \"\"\ncompression_mode: \"\"\nrelative_file_paths:\n  - " +
         file_name + "\nfiles:\n  - path: " + file_name +
         "\n    starting_time:\n      nanoseconds_since_epoch: " + start +
         "\n    duration:\n      nanoseconds: " + duration +
         "\n    message_count: " + std::to_string(messages) +
         "\ncustom_data: ~\nros_distro: \"\"";  // rosbag2 writes $ROS_DISTRO: there is none
    if (indent.empty()) return y;
    std::string out = indent;
    for (char ch : y) out += ch == '\n' ? "\n" + indent : std::string(1, ch);
    return out;
  }
};

BagWriter::BagWriter() : impl_(new Impl) {}
BagWriter::~BagWriter() = default;

bool BagWriter::open(const std::string& folder, const std::string& name,
                     const std::string& imu_topic, const std::string& camera_topic,
                     std::string& error) {
  Impl& w = *impl_;
  w.folder = folder;
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  w.file_name = (name.empty() || name == "." || name == ".." ? "recording" : name) + "_0.mcap";
  w.path = folder + "/" + w.file_name;
  w.imu.topic = imu_topic;
  w.camera.topic = camera_topic;
  w.file = w.out.add(w.path, error);
  if (w.file == nullptr) return false;
  Bytes head, header;
  head.append(kMcapMagic, sizeof kMcapMagic);
  header.string("ros2");
  header.string(written_by());
  head.record(kMcapHeader, header);
  for (const ChannelInfo* c : {&w.imu, &w.camera}) {
    head.record(kMcapSchema, w.schema(*c));
    head.record(kMcapChannel, w.channel(*c));
  }
  if (!w.write(head.data, &w.data_crc)) {
    error = w.error;
    return false;
  }
  return true;
}

bool BagWriter::add_imu(const ImuSample& s) {
  Cdr m;
  m.header(s.t_ns, impl_->imu.frame_id);
  for (double v : {0.0, 0.0, 0.0, 1.0}) m.put(v);  // no orientation
  // Its covariance's first element -1: "no orientation estimate" (sensor_msgs/Imu).
  for (int i = 0; i < 9; ++i) m.put(i == 0 ? -1.0 : 0.0);
  for (int i = 0; i < 3; ++i) m.put(double(s.gyro(i)));
  for (int i = 0; i < 9; ++i) m.put(0.0);  // covariances unknown
  for (int i = 0; i < 3; ++i) m.put(double(s.accel(i)));
  for (int i = 0; i < 9; ++i) m.put(0.0);
  return impl_->add(impl_->imu, s.t_ns, m.data());
}

bool BagWriter::add_image(std::int64_t t_ns, const GrayImage& image) {
  Cdr m;
  m.header(t_ns, impl_->camera.frame_id);
  m.put(std::uint32_t(image.height));
  m.put(std::uint32_t(image.width));
  m.string("mono8");
  m.put(std::uint8_t(0));
  m.put(std::uint32_t(image.width));  // step
  m.bytes(image.pixels, std::size_t(image.width) * std::size_t(image.height));
  return impl_->add(impl_->camera, t_ns, m.data());
}

bool BagWriter::close(std::string& error) {
  Impl& w = *impl_;
  if (!w.finish() || !w.error.empty()) {
    error = w.error.empty() ? w.path + ": not written" : w.error;
    return false;
  }
  std::FILE* meta = w.out.add(w.folder + "/metadata.yaml", error);
  if (meta == nullptr) return false;
  const std::string yaml = "# written by " + written_by() + "\nrosbag2_bagfile_information:\n" +
                           w.bag_metadata("  ") + "\n";
  std::fputs(yaml.c_str(), meta);
  return w.out.commit(error);
}

}  // namespace mirrorcal::io
