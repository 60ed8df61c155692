// libFuzzer target: a ROS 1 bag or an MCAP file as calibrate reads one, every topic's messages
// streamed and decoded as the IMU's or the camera's. Any input gives messages within the file's
// bytes or a message naming the file, never a crash, an overrun or an allocation sized beyond what
// the file's own records state.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <unistd.h>

#include "bag_containers.hpp"
#include "bag_messages.hpp"

namespace {

namespace bag = mirrorcal::io::bag;

constexpr std::uint32_t kMaxPixels = 64 * 48;

void decode(const bag::Topic& topic, const bag::Message& m) {
  std::string what;
  switch (bag::message_type(topic)) {
    case bag::MessageType::kImu: {
      mirrorcal::ImuSample s;
      bag::decode_imu(m, topic.encoding, s, what);
      break;
    }
    case bag::MessageType::kImage: {
      bag::ImageMessage image;
      static std::vector<std::uint8_t> grey(kMaxPixels);
      if (bag::decode_image(m, topic.encoding, image, what) &&
          std::uint64_t{image.width} * image.height <= kMaxPixels)
        bag::image_to_grey(image, grey.data(), what);
      break;
    }
    case bag::MessageType::kCompressedImage: {
      bag::CompressedImageMessage c;
      bag::decode_compressed_image(m, topic.encoding, c, what);
      break;
    }
    case bag::MessageType::kOther: {
      std::int64_t stamp = 0;
      bag::decode_stamp(m, topic.encoding, stamp, what);
      break;
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/fuzz_bag_" + std::to_string(getpid());
  FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr || std::fwrite(data, 1, size, f) != size || std::fclose(f) != 0) std::abort();
  std::string error;
  const auto b = bag::Bag::open(path, error);
  if (!b) {
    if (error.rfind(path, 0) != 0) std::abort();  // the message names the file
    return 0;
  }
  for (const bag::Topic& topic : b->topics()) {
    const auto messages = b->messages(topic);
    bag::Message m;
    mirrorcal::hal::SourceStatus s;
    while ((s = messages->next(m)) == mirrorcal::hal::SourceStatus::kOk) {
      if (m.data == nullptr && m.size > 0) std::abort();
      decode(topic, m);
    }
    if (s == mirrorcal::hal::SourceStatus::kError && messages->error().rfind(path, 0) != 0)
      std::abort();
  }
  return 0;
}
