// The containers ROS users record into, read from their published specifications without ROS:
// ROS 1 bags (format 2.0: http://wiki.ros.org/Bags/Format/2.0; chunks stored, bz2 or lz4), MCAP
// files (https://mcap.dev/spec, version 0; chunks stored, zstd or lz4) and ROS 2 bag folders
// (rosbag2's metadata.yaml over sqlite3 .db3 or MCAP files). Only the containers: a message's
// bytes are read by bag_messages.hpp. Each stream reads its topic's messages from the start of
// the file in bounded memory (one chunk at a time), so a bag of any length streams. Internal to
// io.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::io::bag {

// MCAP's magic, at both ends of a file, and its records' opcodes (mcap.dev/spec), for the reader
// here and the writer (bag_writer.cpp).
constexpr std::uint8_t kMcapMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
enum McapOp : std::uint8_t {
  kMcapHeader = 0x01,
  kMcapFooter = 0x02,
  kMcapSchema = 0x03,
  kMcapChannel = 0x04,
  kMcapMessage = 0x05,
  kMcapChunk = 0x06,
  kMcapMessageIndex = 0x07,
  kMcapChunkIndex = 0x08,
  kMcapStatistics = 0x0b,
  kMcapMetadata = 0x0c,
  kMcapMetadataIndex = 0x0d,
  kMcapSummaryOffset = 0x0e,
  kMcapDataEnd = 0x0f
};

// How a topic's messages are serialised: ROS 1's (packed, little-endian) or ROS 2's CDR.
enum class Encoding { kRos1, kCdr, kOther };

struct Topic {
  std::string name;
  std::string type;  // as the container names it: sensor_msgs/Imu (ROS 1), sensor_msgs/msg/Imu
  Encoding encoding = Encoding::kOther;
  std::string encoding_name;   // as the container names it (messages say what is not read)
  std::uint64_t messages = 0;  // as the container's index counts them (0: it does not say)
};

// One message: its bytes stay valid until the stream's next call.
struct Message {
  std::int64_t log_time_ns = 0;  // when it was recorded (not its header's stamp)
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
  std::uint64_t offset = 0;  // its record's byte in the file (its chunk's, when compressed)
  const char* file = "";     // the file it is in (a ROS 2 bag folder has several)
};

// One topic's messages in the order the container holds them.
class MessageStream {
 public:
  virtual ~MessageStream() = default;
  // kOk with the next message, kEndOfStream, or kError with error() naming the file, the topic
  // and the byte where it went wrong.
  virtual hal::SourceStatus next(Message& message) = 0;
  const std::string& error() const { return error_; }

 protected:
  hal::SourceStatus fail(std::string message) {
    error_ = std::move(message);
    return hal::SourceStatus::kError;
  }
  std::string error_;
};

// A bag: a ROS 1 .bag, an .mcap file, a rosbag2 .db3 file, or a ROS 2 bag folder.
class Bag {
 public:
  // The bag at path, its topics read from its index (its summary, its metadata); null with a
  // message naming the file if it is none of them, is cut off or cannot be read.
  static std::unique_ptr<Bag> open(const std::string& path, std::string& error);
  virtual ~Bag() = default;
  const std::string& path() const { return path_; }
  const std::vector<Topic>& topics() const { return topics_; }
  const Topic* topic(const std::string& name) const;
  // The messages of one of topics() from the start of the bag.
  virtual std::unique_ptr<MessageStream> messages(const Topic& topic) const = 0;

 protected:
  explicit Bag(std::string path) : path_(std::move(path)) {}
  std::string path_;
  std::vector<Topic> topics_;
};

}  // namespace mirrorcal::io::bag
