#include "bag_containers.hpp"

#include <bzlib.h>
#include <lz4frame.h>
#include <sqlite3.h>
#include <yaml-cpp/yaml.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>
#include <string_view>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace mirrorcal::io::bag {

namespace {

std::string at_byte(std::uint64_t offset) {
  return " at byte " + std::to_string(offset);
}

// A file read by offset (pread), its size known when opened.
class File {
 public:
  File() = default;
  File(const File&) = delete;
  File& operator=(const File&) = delete;
  ~File() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool open(const std::string& path, std::string& error) {
    path_ = path;
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    struct stat st {};
    if (fd_ < 0 || ::fstat(fd_, &st) != 0) {
      error = path + ": cannot open: " + std::strerror(errno);
      return false;
    }
    if (!S_ISREG(st.st_mode)) {
      error = path + ": not a regular file";
      return false;
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
    return true;
  }
  // Exactly n bytes at offset; false if the file ends before (or cannot be read).
  bool read(std::uint64_t offset, void* out, std::size_t n) const {
    auto* p = static_cast<char*>(out);
    while (n > 0) {
      const ssize_t r = ::pread(fd_, p, n, static_cast<off_t>(offset));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      p += r;
      offset += static_cast<std::uint64_t>(r);
      n -= static_cast<std::size_t>(r);
    }
    return true;
  }
  bool read(std::uint64_t offset, std::vector<std::uint8_t>& out, std::size_t n) const {
    out.resize(n);  // grows to the largest record read, then stays
    return read(offset, out.data(), n);
  }
  std::uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::string path_;
};

// Little-endian fields of a record in memory, bounds checked: a short record reads as !ok().
class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : p_(data), end_(data + size) {}
  template <typename T>
  T get() {
    T v{};
    if (static_cast<std::size_t>(end_ - p_) < sizeof(T)) {
      ok_ = false;
      p_ = end_;
      return v;
    }
    std::memcpy(&v, p_, sizeof(T));  // the hosts and boards mirrorcal builds for are little-endian
    p_ += sizeof(T);
    return v;
  }
  std::string_view bytes(std::uint64_t n) {
    if (static_cast<std::uint64_t>(end_ - p_) < n) {
      ok_ = false;
      p_ = end_;
      return {};
    }
    const std::string_view s(reinterpret_cast<const char*>(p_), static_cast<std::size_t>(n));
    p_ += n;
    return s;
  }
  std::string_view string32() { return bytes(get<std::uint32_t>()); }  // MCAP's string, ROS 1's
  bool ok() const { return ok_; }
  std::size_t left() const { return static_cast<std::size_t>(end_ - p_); }
  const std::uint8_t* here() const { return p_; }

 private:
  const std::uint8_t* p_;
  const std::uint8_t* end_;
  bool ok_ = true;
};

Encoding encoding_named(std::string_view name) {
  if (name == "ros1") return Encoding::kRos1;
  if (name == "cdr") return Encoding::kCdr;
  return Encoding::kOther;
}

// --- Decompression -------------------------------------------------------------------------------

// The compressions ROS 1 bags (bz2, lz4) and MCAP files (zstd, lz4) use for their chunks, each
// into a buffer of the size the chunk states.
class Decompressor {
 public:
  Decompressor() = default;
  Decompressor(const Decompressor&) = delete;
  Decompressor& operator=(const Decompressor&) = delete;
  ~Decompressor() {
    if (lz4_ != nullptr) LZ4F_freeDecompressionContext(lz4_);
    if (zstd_ != nullptr) ZSTD_freeDCtx(zstd_);
  }
  // A chunk's size as its file states it, before anything is allocated: a chunk holds whole
  // messages, and the largest camera image is far below this.
  static constexpr std::uint64_t kMaxChunkBytes = std::uint64_t(512) << 20;

  // in into out (resized to size); false with what went wrong in error.
  bool run(std::string_view compression, const std::vector<std::uint8_t>& in,
           std::vector<std::uint8_t>& out, std::uint64_t size, std::string& error) {
    if (size > kMaxChunkBytes) {
      error = "it states " + std::to_string(size) +
              " bytes uncompressed, more than the 512 MiB mirrorcal reads in one chunk";
      return false;
    }
    out.resize(static_cast<std::size_t>(size));
    if (compression == "bz2") return bz2(in, out, error);
    if (compression == "lz4") return lz4(in, out, error);
    if (compression == "zstd") return zstd(in, out, error);
    error = "its compression '" + std::string(compression) + "' is not one mirrorcal reads";
    return false;
  }

 private:
  static bool bz2(const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>& out,
                  std::string& error) {
    auto n = static_cast<unsigned>(out.size());
    const int r =
        BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out.data()), &n,
                                   const_cast<char*>(reinterpret_cast<const char*>(in.data())),
                                   static_cast<unsigned>(in.size()), 0, 0);
    if (r != BZ_OK || n != out.size()) {
      error = "bz2 cannot decompress it (error " + std::to_string(r) + ")";
      return false;
    }
    return true;
  }
  bool lz4(const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>& out,
           std::string& error) {
    if (lz4_ == nullptr && LZ4F_isError(LZ4F_createDecompressionContext(&lz4_, LZ4F_VERSION))) {
      error = "lz4 cannot be set up";
      return false;
    }
    LZ4F_resetDecompressionContext(lz4_);
    std::size_t in_at = 0, out_at = 0;
    for (;;) {
      std::size_t in_n = in.size() - in_at, out_n = out.size() - out_at;
      const std::size_t r =
          LZ4F_decompress(lz4_, out.data() + out_at, &out_n, in.data() + in_at, &in_n, nullptr);
      if (LZ4F_isError(r)) {
        error = std::string("lz4 cannot decompress it: ") + LZ4F_getErrorName(r);
        return false;
      }
      in_at += in_n;
      out_at += out_n;
      if (r == 0) break;  // the frame is complete
      if (in_n == 0 && out_n == 0) {
        error = "lz4: its data end before the frame does";
        return false;
      }
    }
    if (out_at != out.size()) {
      error = "lz4: it decompresses to " + std::to_string(out_at) + " bytes, not the " +
              std::to_string(out.size()) + " it states";
      return false;
    }
    return true;
  }
  bool zstd(const std::vector<std::uint8_t>& in, std::vector<std::uint8_t>& out,
            std::string& error) {
    if (zstd_ == nullptr) zstd_ = ZSTD_createDCtx();
    const std::size_t r = ZSTD_decompressDCtx(zstd_, out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(r) || r != out.size()) {
      error = std::string("zstd cannot decompress it: ") +
              (ZSTD_isError(r) ? ZSTD_getErrorName(r) : "its size is not the one it states");
      return false;
    }
    return true;
  }

  LZ4F_dctx* lz4_ = nullptr;
  ZSTD_DCtx* zstd_ = nullptr;
};

// A topic's messages read chunk by chunk: the records of the chunk in hand, then on through the
// file to the next chunk.
class ChunkStream : public MessageStream {
 public:
  hal::SourceStatus next(Message& m) final {
    if (!error_.empty()) return hal::SourceStatus::kError;
    for (;;) {
      while (at_ < inner_.size()) {
        const hal::SourceStatus s = chunk_record(m);
        if (s != hal::SourceStatus::kEndOfStream) return s;  // a message of ours, or an error
      }
      const hal::SourceStatus s = advance(m);
      if (s != hal::SourceStatus::kNotReady) return s;
    }
  }

 protected:
  ChunkStream(const std::string& path, std::string topic) : topic_(std::move(topic)) {
    std::string error;
    if (!file_.open(path, error)) fail(error);
  }
  // The record at at_ of the chunk in hand (inner_), at_ moved past it: kOk with a message of
  // ours, kEndOfStream if it is none, kError.
  virtual hal::SourceStatus chunk_record(Message& m) = 0;
  // On beyond the chunk in hand: kNotReady once the next chunk is in inner_ (or a record outside
  // chunks was skipped), kOk with a message of ours outside chunks, kEndOfStream, kError.
  virtual hal::SourceStatus advance(Message& m) = 0;

  std::string topic_;
  File file_;
  Decompressor decompress_;
  std::vector<std::uint8_t> compressed_, inner_;
  std::size_t at_ = 0;
  std::uint64_t chunk_offset_ = 0;  // the chunk in hand's, for messages
};

// --- ROS 1 bags ------------------------------------------------------------------------------

constexpr std::string_view kRos1Magic = "#ROSBAG V2.0\n";
enum Ros1Op : std::uint8_t {
  kRos1Message = 0x02,
  kRos1BagHeader = 0x03,
  kRos1IndexData = 0x04,
  kRos1Chunk = 0x05,
  kRos1ChunkInfo = 0x06,
  kRos1Connection = 0x07
};

// A record's header: fields of "name=value", the values binary.
class Ros1Fields {
 public:
  explicit Ros1Fields(std::string_view header) : header_(header) {}
  bool find(std::string_view name, std::string_view& value) const {
    Bytes b(reinterpret_cast<const std::uint8_t*>(header_.data()), header_.size());
    while (b.left() > 0) {
      const std::string_view field = b.string32();
      if (!b.ok()) return false;
      const std::size_t eq = field.find('=');
      if (eq != std::string_view::npos && field.substr(0, eq) == name) {
        value = field.substr(eq + 1);
        return true;
      }
    }
    return false;
  }
  template <typename T>
  bool get(std::string_view name, T& v) const {
    std::string_view value;
    if (!find(name, value) || value.size() != sizeof(T)) return false;
    std::memcpy(&v, value.data(), sizeof(T));
    return true;
  }
  std::uint8_t op() const {
    std::uint8_t op = 0;
    return get("op", op) ? op : 0;
  }

 private:
  std::string_view header_;
};

std::int64_t ros1_time_ns(std::uint64_t t) {  // u32 seconds, then u32 nanoseconds
  return static_cast<std::int64_t>(t & 0xffffffffu) * 1000000000 +
         static_cast<std::int64_t>(t >> 32);
}

// A record read from the file: its header, and where its data lie.
struct Ros1Record {
  std::uint64_t offset = 0, data_offset = 0, end = 0;
  std::uint32_t data_size = 0;
  std::vector<std::uint8_t> header;
  Ros1Fields fields() const {
    return Ros1Fields({reinterpret_cast<const char*>(header.data()), header.size()});
  }
};

// The record at offset, its header read; false (and why in error) if the file ends inside it.
bool read_ros1_record(const File& f, std::uint64_t offset, Ros1Record& r, std::string& error) {
  std::uint32_t header_size = 0, data_size = 0;
  r.offset = offset;
  if (!f.read(offset, &header_size, 4) || offset + 8 + header_size > f.size() ||
      !f.read(offset + 4, r.header, header_size) ||
      !f.read(offset + 4 + header_size, &data_size, 4) ||
      offset + 8 + header_size + data_size > f.size()) {
    error = f.path() + ": cut off in the record" + at_byte(offset) + " (the file ends at byte " +
            std::to_string(f.size()) + ")";
    return false;
  }
  r.data_offset = offset + 8 + header_size;
  r.data_size = data_size;
  r.end = r.data_offset + data_size;
  return true;
}

class Ros1Bag final : public Bag {
 public:
  explicit Ros1Bag(std::string path) : Bag(std::move(path)) {}
  bool open(std::string& error);
  std::unique_ptr<MessageStream> messages(const Topic& topic) const override;

  struct Chunk {
    std::uint64_t offset = 0;
    std::set<std::uint32_t> connections;
  };

 private:
  bool read_index(std::uint64_t index_pos, std::string& error);
  bool add_connection(const Ros1Fields& fields, const std::uint8_t* data, std::size_t size,
                      std::uint64_t offset, std::string& error);

  File file_;
  std::uint64_t data_start_ = 0;
  std::map<std::uint32_t, std::size_t> topic_of_connection_;  // into topics_
  std::vector<Chunk> chunks_;                                 // in file order
};

class Ros1Stream final : public ChunkStream {
 public:
  Ros1Stream(const std::string& path, const Topic& topic, std::set<std::uint32_t> connections,
             const std::vector<Ros1Bag::Chunk>& chunks)
      : ChunkStream(path, topic.name), connections_(std::move(connections)) {
    for (const Ros1Bag::Chunk& c : chunks)
      for (std::uint32_t conn : c.connections)
        if (connections_.count(conn) != 0) {
          chunks_.push_back(c.offset);
          break;
        }
  }

 private:
  hal::SourceStatus advance(Message&) override {
    if (next_chunk_ == chunks_.size()) return hal::SourceStatus::kEndOfStream;
    return load_chunk(chunks_[next_chunk_++]) ? hal::SourceStatus::kNotReady
                                              : hal::SourceStatus::kError;
  }
  bool load_chunk(std::uint64_t offset) {
    std::string error;
    Ros1Record r;
    if (!read_ros1_record(file_, offset, r, error)) return bad(error);
    const Ros1Fields fields = r.fields();
    std::string_view compression;
    std::uint32_t size = 0;
    if (fields.op() != kRos1Chunk || !fields.find("compression", compression) ||
        !fields.get("size", size))
      return bad(file_.path() + ": the index names a chunk" + at_byte(offset) + " that is not one");
    chunk_offset_ = offset;
    at_ = 0;
    if (compression == "none") {
      if (!file_.read(r.data_offset, inner_, r.data_size)) return bad(cut(offset));
      return true;
    }
    if (!file_.read(r.data_offset, compressed_, r.data_size)) return bad(cut(offset));
    if (!decompress_.run(compression, compressed_, inner_, size, error))
      return bad(file_.path() + ": the chunk" + at_byte(offset) + " (topic " + topic_ +
                 "): " + error);
    return true;
  }
  // The chunk's next record: kOk if it is a message of ours, kEndOfStream if not (or none left).
  hal::SourceStatus chunk_record(Message& m) override {
    Bytes b(inner_.data() + at_, inner_.size() - at_);
    const std::string_view header = b.string32();
    const std::string_view data = b.string32();
    if (!b.ok()) {
      fail(file_.path() + ": the chunk" + at_byte(chunk_offset_) + " ends inside a record (topic " +
           topic_ + ")");
      return hal::SourceStatus::kError;
    }
    at_ = inner_.size() - b.left();
    const Ros1Fields fields(header);
    std::uint32_t conn = 0;
    std::uint64_t time = 0;
    if (fields.op() != kRos1Message || !fields.get("conn", conn) || connections_.count(conn) == 0)
      return hal::SourceStatus::kEndOfStream;
    if (!fields.get("time", time)) {
      fail(file_.path() + ": a message of " + topic_ + " without its time, in the chunk" +
           at_byte(chunk_offset_));
      return hal::SourceStatus::kError;
    }
    m.log_time_ns = ros1_time_ns(time);
    m.data = reinterpret_cast<const std::uint8_t*>(data.data());
    m.size = data.size();
    m.offset = chunk_offset_;
    m.file = file_.path().c_str();
    return hal::SourceStatus::kOk;
  }
  std::string cut(std::uint64_t offset) const {
    return file_.path() + ": cut off in the chunk" + at_byte(offset) + " (topic " + topic_ + ")";
  }
  bool bad(const std::string& message) {
    fail(message);
    return false;
  }

  std::set<std::uint32_t> connections_;
  std::vector<std::uint64_t> chunks_;  // the chunks holding messages of ours
  std::size_t next_chunk_ = 0;
};

bool Ros1Bag::open(std::string& error) {
  if (!file_.open(path_, error)) return false;
  char magic[13] = {};
  if (!file_.read(0, magic, sizeof magic) || std::string_view(magic, 13) != kRos1Magic) {
    error = path_ + ": not a ROS 1 bag of format 2.0 (it does not begin with '#ROSBAG V2.0')";
    if (std::string_view(magic, 9) == "#ROSBAG V")
      error += "; older bags are migrated by `rosbag fix`";
    return false;
  }
  Ros1Record header;
  if (!read_ros1_record(file_, sizeof magic, header, error)) return false;
  std::uint64_t index_pos = 0;
  if (header.fields().op() != kRos1BagHeader || !header.fields().get("index_pos", index_pos)) {
    error = path_ + ": its first record is not the bag header";
    return false;
  }
  data_start_ = header.end;
  if (index_pos == 0) {
    error = path_ +
            ": a bag that was never closed (it has no index: its recording was stopped before it "
            "finished); `rosbag reindex` it, which also drops a chunk cut off at its end";
    return false;
  }
  if (index_pos < data_start_ || index_pos >= file_.size()) {
    error = path_ + ": cut off: its index should begin" + at_byte(index_pos) +
            ", and the file ends at byte " + std::to_string(file_.size());
    return false;
  }
  return read_index(index_pos, error);
}

// After the chunks: the connections (topics and their types), then a record per chunk naming the
// connections it holds messages of.
bool Ros1Bag::read_index(std::uint64_t index_pos, std::string& error) {
  std::vector<std::uint8_t> data;
  for (std::uint64_t at = index_pos; at < file_.size();) {
    Ros1Record r;
    if (!read_ros1_record(file_, at, r, error) || !file_.read(r.data_offset, data, r.data_size))
      return false;
    const Ros1Fields fields = r.fields();
    if (fields.op() == kRos1Connection) {
      if (!add_connection(fields, data.data(), data.size(), at, error)) return false;
    } else if (fields.op() == kRos1ChunkInfo) {
      Chunk chunk;
      std::uint32_t count = 0;
      if (!fields.get("chunk_pos", chunk.offset) || !fields.get("count", count)) {
        error = path_ + ": a chunk's index" + at_byte(at) + " lacks chunk_pos or count";
        return false;
      }
      Bytes b(data.data(), data.size());
      for (std::uint32_t k = 0; k < count && b.ok(); ++k) {
        const auto conn = b.get<std::uint32_t>();
        const auto messages = b.get<std::uint32_t>();
        chunk.connections.insert(conn);
        const auto it = topic_of_connection_.find(conn);
        if (it != topic_of_connection_.end()) topics_[it->second].messages += messages;
      }
      if (!b.ok()) {
        error = path_ + ": a chunk's index" + at_byte(at) + " is cut short";
        return false;
      }
      chunks_.push_back(std::move(chunk));
    }
    at = r.end;
  }
  std::sort(chunks_.begin(), chunks_.end(),
            [](const Chunk& a, const Chunk& b) { return a.offset < b.offset; });
  return true;
}

bool Ros1Bag::add_connection(const Ros1Fields& fields, const std::uint8_t* data, std::size_t size,
                             std::uint64_t offset, std::string& error) {
  std::uint32_t conn = 0;
  std::string_view topic, type;
  const Ros1Fields connection_header({reinterpret_cast<const char*>(data), size});
  if (!fields.get("conn", conn) || !fields.find("topic", topic) ||
      !connection_header.find("type", type)) {
    error = path_ + ": a connection record" + at_byte(offset) + " lacks its topic or type";
    return false;
  }
  auto it =
      std::find_if(topics_.begin(), topics_.end(), [&](const Topic& t) { return t.name == topic; });
  if (it == topics_.end()) {
    topics_.push_back({std::string(topic), std::string(type), Encoding::kRos1, "ros1", 0});
    it = topics_.end() - 1;
  }
  topic_of_connection_[conn] = static_cast<std::size_t>(it - topics_.begin());
  return true;
}

std::unique_ptr<MessageStream> Ros1Bag::messages(const Topic& topic) const {
  std::set<std::uint32_t> connections;
  for (const auto& [conn, index] : topic_of_connection_)
    if (topics_[index].name == topic.name) connections.insert(conn);
  return std::make_unique<Ros1Stream>(path_, topic, std::move(connections), chunks_);
}

// --- MCAP -----------------------------------------------------------------------------------

struct McapChannel {
  std::string topic, encoding;
  std::uint16_t schema = 0;
};

// Schemas and channels as a file's records define them (in its summary, or as they come).
struct McapDefinitions {
  std::map<std::uint16_t, std::string> schema_names;
  std::map<std::uint16_t, McapChannel> channels;
  // A Schema or Channel record's content; false if it is cut short.
  bool add(std::uint8_t op, Bytes b) {
    if (op == kMcapSchema) {
      const auto id = b.get<std::uint16_t>();
      const std::string_view name = b.string32();
      if (b.ok()) schema_names[id] = std::string(name);
    } else if (op == kMcapChannel) {
      const auto id = b.get<std::uint16_t>();
      McapChannel c;
      c.schema = b.get<std::uint16_t>();
      c.topic = std::string(b.string32());
      c.encoding = std::string(b.string32());
      if (b.ok()) channels[id] = std::move(c);
    }
    return b.ok();
  }
};

class McapStream final : public ChunkStream {
 public:
  McapStream(const std::string& path, const Topic& topic, std::uint64_t data_end)
      : ChunkStream(path, topic.name), data_end_(data_end) {}
  // The schemas and channels met so far.
  const McapDefinitions& definitions() const { return definitions_; }

 private:
  hal::SourceStatus chunk_record(Message& m) override {
    return record_in(inner_, at_, chunk_offset_, m);
  }
  hal::SourceStatus advance(Message& m) override {
    if (done_) return hal::SourceStatus::kEndOfStream;
    const hal::SourceStatus s = top_record(m);
    if (s != hal::SourceStatus::kEndOfStream) return s;
    return done_ ? hal::SourceStatus::kEndOfStream : hal::SourceStatus::kNotReady;
  }
  // The next record of the data section: a message of ours (kOk), a chunk loaded, or another
  // record skipped (both kEndOfStream, with more to come unless done_).
  hal::SourceStatus top_record(Message& m) {
    std::uint8_t head[9];
    if (offset_ + 9 > data_end_ || !file_.read(offset_, head, 9)) {
      done_ = true;  // no DataEnd record: the data section ends where the summary begins
      return hal::SourceStatus::kEndOfStream;
    }
    std::uint64_t length = 0;
    std::memcpy(&length, head + 1, 8);
    const std::uint64_t offset = offset_;
    if (length > data_end_ - offset - 9)
      return fail(file_.path() + ": cut off in the record" + at_byte(offset) + " (topic " + topic_ +
                  "; the file ends at byte " + std::to_string(file_.size()) + ")");
    offset_ += 9 + length;
    switch (head[0]) {
      case kMcapDataEnd:
      case kMcapFooter:
        done_ = true;
        return hal::SourceStatus::kEndOfStream;
      case kMcapChunk:
        return load_chunk(offset, length);
      case kMcapSchema:
      case kMcapChannel:
      case kMcapMessage: {
        if (!file_.read(offset, record_, static_cast<std::size_t>(9 + length)))
          return fail(file_.path() + ": cannot read the record" + at_byte(offset));
        std::size_t at = 0;
        return record_in(record_, at, offset, m);
      }
      default:  // attachments, metadata, indexes: not ours; unknown records are skipped by rule
        return hal::SourceStatus::kEndOfStream;
    }
  }
  hal::SourceStatus load_chunk(std::uint64_t offset, std::uint64_t length) {
    if (!file_.read(offset + 9, record_, static_cast<std::size_t>(length)))
      return fail(file_.path() + ": cannot read the chunk" + at_byte(offset));
    Bytes b(record_.data(), record_.size());
    b.get<std::uint64_t>();  // message_start_time
    b.get<std::uint64_t>();  // message_end_time
    const auto size = b.get<std::uint64_t>();
    const auto crc = b.get<std::uint32_t>();
    const std::string_view compression = b.string32();
    const auto records = b.get<std::uint64_t>();
    if (!b.ok() || records > b.left())
      return fail(file_.path() + ": the chunk" + at_byte(offset) + " is malformed (topic " +
                  topic_ + ")");
    chunk_offset_ = offset;
    at_ = 0;
    if (compression.empty()) {
      inner_.assign(b.here(), b.here() + records);
    } else {
      compressed_.assign(b.here(), b.here() + records);
      std::string error;
      if (!decompress_.run(compression, compressed_, inner_, size, error))
        return fail(file_.path() + ": the chunk" + at_byte(offset) + " (topic " + topic_ +
                    "): " + error);
    }
    // The CRC of the uncompressed records (0: the writer computed none).
    if (crc != 0 && crc32(0L, inner_.data(), static_cast<uInt>(inner_.size())) != crc)
      return fail(file_.path() + ": the chunk" + at_byte(offset) +
                  " does not match its CRC (topic " + topic_ + "; the file is damaged)");
    return hal::SourceStatus::kEndOfStream;
  }
  // The record at `at` of records (advanced past it): a Message of our topic is kOk; Schema and
  // Channel records are learnt.
  hal::SourceStatus record_in(const std::vector<std::uint8_t>& records, std::size_t& at,
                              std::uint64_t offset, Message& m) {
    Bytes b(records.data() + at, records.size() - at);
    const auto op = b.get<std::uint8_t>();
    const auto length = b.get<std::uint64_t>();
    if (!b.ok() || length > b.left())
      return fail(file_.path() + ": a record ends beyond its chunk" + at_byte(offset) + " (topic " +
                  topic_ + ")");
    Bytes content(b.here(), static_cast<std::size_t>(length));
    at += 9 + static_cast<std::size_t>(length);
    if (op == kMcapSchema || op == kMcapChannel) {
      if (!definitions_.add(op, content))
        return fail(file_.path() + ": a schema or channel record" + at_byte(offset) +
                    " is cut short");
      return hal::SourceStatus::kEndOfStream;
    }
    if (op != kMcapMessage) return hal::SourceStatus::kEndOfStream;
    const auto channel = content.get<std::uint16_t>();
    content.get<std::uint32_t>();  // sequence
    const auto log_time = content.get<std::uint64_t>();
    content.get<std::uint64_t>();  // publish_time
    if (!content.ok())
      return fail(file_.path() + ": a message record" + at_byte(offset) + " is cut short");
    const auto it = definitions_.channels.find(channel);
    if (it == definitions_.channels.end() || it->second.topic != topic_)
      return hal::SourceStatus::kEndOfStream;
    m.log_time_ns = static_cast<std::int64_t>(log_time);
    m.data = content.here();
    m.size = content.left();
    m.offset = offset;
    m.file = file_.path().c_str();
    return hal::SourceStatus::kOk;
  }

  std::uint64_t data_end_;
  McapDefinitions definitions_;
  std::vector<std::uint8_t> record_;  // a record outside chunks
  std::uint64_t offset_ = sizeof kMcapMagic;
  bool done_ = false;
};

class McapBag final : public Bag {
 public:
  explicit McapBag(std::string path) : Bag(std::move(path)) {}
  bool open(std::string& error);
  std::unique_ptr<MessageStream> messages(const Topic& topic) const override {
    return std::make_unique<McapStream>(path_, topic, data_end_);
  }

 private:
  bool read_summary(std::uint64_t from, std::uint64_t to, McapDefinitions& d,
                    std::map<std::uint16_t, std::uint64_t>& counts, std::string& error);
  bool scan_definitions(McapDefinitions& d, std::string& error);

  File file_;
  std::uint64_t data_end_ = 0;  // where the summary (or the footer) begins
};

bool McapBag::open(std::string& error) {
  if (!file_.open(path_, error)) return false;
  std::uint8_t magic[8] = {};
  if (!file_.read(0, magic, 8) || std::memcmp(magic, kMcapMagic, 8) != 0) {
    error = path_ + ": not an MCAP file (it does not begin with MCAP's magic bytes)";
    return false;
  }
  // The footer: opcode, length 20, summary_start, summary_offset_start, summary_crc; then magic.
  constexpr std::uint64_t kTail = 1 + 8 + 20 + 8;
  std::uint8_t tail[kTail] = {};
  if (file_.size() < 8 + kTail || !file_.read(file_.size() - kTail, tail, kTail) ||
      std::memcmp(tail + kTail - 8, kMcapMagic, 8) != 0 || tail[0] != kMcapFooter) {
    error = path_ +
            ": cut off: it does not end with MCAP's footer and magic bytes (the file ends at "
            "byte " +
            std::to_string(file_.size()) + "; its writer did not finish it)";
    return false;
  }
  std::uint64_t summary_start = 0;
  std::memcpy(&summary_start, tail + 9, 8);
  data_end_ = summary_start != 0 ? summary_start : file_.size() - kTail;
  McapDefinitions d;
  std::map<std::uint16_t, std::uint64_t> counts;
  if (summary_start != 0 && !read_summary(summary_start, file_.size() - kTail, d, counts, error))
    return false;
  if (d.channels.empty() && !scan_definitions(d, error)) return false;
  for (const auto& [id, channel] : d.channels) {
    if (topic(channel.topic) != nullptr) continue;  // another channel of the same topic
    const auto schema = d.schema_names.find(channel.schema);
    topics_.push_back({channel.topic, schema != d.schema_names.end() ? schema->second : "",
                       encoding_named(channel.encoding), channel.encoding,
                       counts.count(id) != 0 ? counts[id] : 0});
  }
  return true;
}

// The summary section: schemas, channels and the statistics' message counts per channel.
bool McapBag::read_summary(std::uint64_t from, std::uint64_t to, McapDefinitions& d,
                           std::map<std::uint16_t, std::uint64_t>& counts, std::string& error) {
  std::vector<std::uint8_t> summary;
  if (from > to || !file_.read(from, summary, static_cast<std::size_t>(to - from))) {
    error = path_ + ": its footer places the summary" + at_byte(from) + ", outside the file";
    return false;
  }
  Bytes b(summary.data(), summary.size());
  while (b.left() > 0) {
    const std::uint64_t offset = from + (summary.size() - b.left());
    const auto op = b.get<std::uint8_t>();
    const auto length = b.get<std::uint64_t>();
    if (!b.ok() || length > b.left()) {
      error = path_ + ": a summary record" + at_byte(offset) + " runs beyond the summary";
      return false;
    }
    Bytes content(b.here(), static_cast<std::size_t>(length));
    b.bytes(length);
    if (op == kMcapStatistics) {
      // message, schema, channel, attachment, metadata and chunk counts; start and end times
      content.bytes(8 + 2 + 4 + 4 + 4 + 4 + 8 + 8);
      const auto map_bytes = content.get<std::uint32_t>();
      Bytes map(content.here(), std::min<std::size_t>(map_bytes, content.left()));
      while (map.left() >= 10) {
        const auto channel = map.get<std::uint16_t>();
        counts[channel] = map.get<std::uint64_t>();
      }
    } else if (!d.add(op, content)) {
      error = path_ + ": a schema or channel record" + at_byte(offset) + " is cut short";
      return false;
    }
  }
  return true;
}

// A file whose summary does not list its channels (it need not): its schemas and channels from
// the data section, chunks and all.
bool McapBag::scan_definitions(McapDefinitions& d, std::string& error) {
  const Topic none{"", "", Encoding::kOther, "", 0};  // no channel has an empty topic
  McapStream scan(path_, none, data_end_);
  Message m;
  if (scan.next(m) == hal::SourceStatus::kError) {
    error = scan.error();
    return false;
  }
  d = scan.definitions();
  return true;
}

// --- rosbag2's sqlite3 storage ---------------------------------------------------------------

class SqliteStream final : public MessageStream {
 public:
  SqliteStream(const std::string& path, const std::string& topic) : path_(path), topic_(topic) {
    if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK ||
        sqlite3_prepare_v2(db_,
                           "SELECT m.timestamp, m.data, m.id FROM messages m JOIN topics t ON "
                           "m.topic_id = t.id WHERE t.name = ?1 ORDER BY m.timestamp",
                           -1, &query_, nullptr) != SQLITE_OK ||
        sqlite3_bind_text(query_, 1, topic.c_str(), -1, SQLITE_STATIC) != SQLITE_OK)
      fail(path + ": " + (db_ != nullptr ? sqlite3_errmsg(db_) : "cannot open") + " (topic " +
           topic + ")");
  }
  ~SqliteStream() override {
    sqlite3_finalize(query_);
    sqlite3_close(db_);
  }
  hal::SourceStatus next(Message& m) override {
    if (!error_.empty()) return hal::SourceStatus::kError;
    const int r = sqlite3_step(query_);
    if (r == SQLITE_DONE) return hal::SourceStatus::kEndOfStream;
    if (r != SQLITE_ROW)
      return fail(path_ + ": " + sqlite3_errmsg(db_) + " (topic " + topic_ + ")");
    m.log_time_ns = sqlite3_column_int64(query_, 0);
    m.data = static_cast<const std::uint8_t*>(sqlite3_column_blob(query_, 1));
    m.size = static_cast<std::size_t>(sqlite3_column_bytes(query_, 1));
    m.offset = static_cast<std::uint64_t>(sqlite3_column_int64(query_, 2));  // the row's id
    m.file = path_.c_str();
    return hal::SourceStatus::kOk;
  }

 private:
  std::string path_, topic_;
  sqlite3* db_ = nullptr;
  sqlite3_stmt* query_ = nullptr;
};

class SqliteBag final : public Bag {
 public:
  explicit SqliteBag(std::string path) : Bag(std::move(path)) {}
  bool open(std::string& error) {
    sqlite3* db = nullptr;
    sqlite3_stmt* q = nullptr;
    const bool ok =
        sqlite3_open_v2(path_.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK &&
        sqlite3_prepare_v2(db,
                           "SELECT t.name, t.type, t.serialization_format, (SELECT COUNT(*) FROM "
                           "messages m WHERE m.topic_id = t.id) FROM topics t ORDER BY t.id",
                           -1, &q, nullptr) == SQLITE_OK;
    int r = SQLITE_ERROR;
    while (ok && (r = sqlite3_step(q)) == SQLITE_ROW) {
      const auto text = [&](int column) {
        const unsigned char* s = sqlite3_column_text(q, column);
        return std::string(s != nullptr ? reinterpret_cast<const char*>(s) : "");
      };
      const std::string format = text(2);
      topics_.push_back({text(0), text(1), encoding_named(format), format,
                         static_cast<std::uint64_t>(sqlite3_column_int64(q, 3))});
    }
    if (r != SQLITE_DONE)
      error = path_ + ": not a rosbag2 sqlite3 file (" +
              (db != nullptr ? sqlite3_errmsg(db) : "cannot open") + ")";
    sqlite3_finalize(q);
    sqlite3_close(db);
    return r == SQLITE_DONE;
  }
  std::unique_ptr<MessageStream> messages(const Topic& topic) const override {
    return std::make_unique<SqliteStream>(path_, topic.name);
  }
};

// --- ROS 2 bag folders -------------------------------------------------------------------------

std::unique_ptr<Bag> open_file(const std::string& path, std::string& error);

// A topic's messages through the folder's files in turn (a bag split by size or duration).
class FilesStream final : public MessageStream {
 public:
  FilesStream(const std::vector<std::unique_ptr<Bag>>& files, const std::string& topic)
      : files_(files), topic_(topic) {}
  hal::SourceStatus next(Message& m) override {
    while (error_.empty()) {
      if (current_ != nullptr) {
        const hal::SourceStatus s = current_->next(m);
        if (s == hal::SourceStatus::kError) return fail(current_->error());
        if (s == hal::SourceStatus::kOk) return s;
        current_.reset();
      }
      if (next_file_ == files_.size()) return hal::SourceStatus::kEndOfStream;
      const Bag& file = *files_[next_file_++];
      if (const Topic* t = file.topic(topic_)) current_ = file.messages(*t);
    }
    return hal::SourceStatus::kError;
  }

 private:
  const std::vector<std::unique_ptr<Bag>>& files_;
  std::string topic_;
  std::size_t next_file_ = 0;
  std::unique_ptr<MessageStream> current_;
};

class Rosbag2Folder final : public Bag {
 public:
  explicit Rosbag2Folder(std::string path) : Bag(std::move(path)) {}
  bool open(std::string& error) {
    const std::string metadata = path_ + "/metadata.yaml";
    std::vector<std::string> files;
    try {
      const YAML::Node info = YAML::LoadFile(metadata)["rosbag2_bagfile_information"];
      if (!info || !info["relative_file_paths"] || !info["relative_file_paths"].IsSequence()) {
        error = metadata +
                ": not a ROS 2 bag's metadata (no rosbag2_bagfile_information with "
                "relative_file_paths)";
        return false;
      }
      for (const YAML::Node& f : info["relative_file_paths"]) files.push_back(f.as<std::string>());
    } catch (const YAML::Exception& e) {
      error = metadata + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg;
      return false;
    }
    if (files.empty()) {
      error = metadata + ": names no storage file (relative_file_paths is empty)";
      return false;
    }
    for (const std::string& f : files) {
      auto bag = open_file(path_ + "/" + f, error);
      if (!bag) return false;
      for (const Topic& t : bag->topics()) {
        auto it = std::find_if(topics_.begin(), topics_.end(),
                               [&](const Topic& u) { return u.name == t.name; });
        if (it == topics_.end())
          topics_.push_back(t);
        else
          it->messages += t.messages;
      }
      files_.push_back(std::move(bag));
    }
    return true;
  }
  std::unique_ptr<MessageStream> messages(const Topic& topic) const override {
    return std::make_unique<FilesStream>(files_, topic.name);
  }

 private:
  std::vector<std::unique_ptr<Bag>> files_;
};

bool ends_with(const std::string& s, std::string_view suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix.data(), suffix.size()) == 0;
}

template <typename B>
std::unique_ptr<Bag> opened(std::unique_ptr<B> bag, std::string& error) {
  if (!bag->open(error)) return nullptr;
  return bag;
}

// A single file, told by its first bytes (a .db3 by its extension: SQLite's header is generic).
std::unique_ptr<Bag> open_file(const std::string& path, std::string& error) {
  File f;
  if (!f.open(path, error)) return nullptr;
  char head[13] = {};
  f.read(0, head, sizeof head);
  if (std::memcmp(head, kMcapMagic, 8) == 0) return opened(std::make_unique<McapBag>(path), error);
  if (std::string_view(head, 9) == "#ROSBAG V")
    return opened(std::make_unique<Ros1Bag>(path), error);
  if (ends_with(path, ".db3")) return opened(std::make_unique<SqliteBag>(path), error);
  error = path + ": neither a ROS 1 bag, an MCAP file nor a rosbag2 .db3 file";
  return nullptr;
}

}  // namespace

const Topic* Bag::topic(const std::string& name) const {
  const auto it =
      std::find_if(topics_.begin(), topics_.end(), [&](const Topic& t) { return t.name == name; });
  return it != topics_.end() ? &*it : nullptr;
}

std::unique_ptr<Bag> Bag::open(const std::string& path, std::string& error) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    if (!std::filesystem::exists(path + "/metadata.yaml", ec)) {
      error = path + ": a folder without metadata.yaml is not a ROS 2 bag";
      return nullptr;
    }
    return opened(std::make_unique<Rosbag2Folder>(path), error);
  }
  return open_file(path, error);
}

}  // namespace mirrorcal::io::bag
