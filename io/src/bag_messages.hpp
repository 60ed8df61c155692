// The messages a calibration reads from a bag, in ROS 1's serialisation and ROS 2's CDR:
// sensor_msgs Imu, Image and CompressedImage. Their stamps are their headers' (the sensor's time,
// as Kalibr reads them), not the times they were recorded at. Internal to io.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "bag_containers.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::io::bag {

enum class MessageType { kImu, kImage, kCompressedImage, kOther };

// The type a topic carries, from its ROS 1 or ROS 2 name (sensor_msgs/Imu, sensor_msgs/msg/Imu).
MessageType message_type(const Topic& topic);

struct ImageMessage {
  std::int64_t stamp_ns = 0;
  std::uint32_t width = 0, height = 0, step = 0;
  std::string_view encoding;  // sensor_msgs/image_encodings: mono8, rgb8, yuv422, ...
  bool big_endian = false;
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
};

struct CompressedImageMessage {
  std::int64_t stamp_ns = 0;
  std::string_view format;  // "png", "jpeg", or image_transport's "mono8; png compressed"
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
};

// Each false with what is wrong in `what` (the caller names the file, topic and offset).
bool decode_imu(const Message& m, Encoding e, ImuSample& out, std::string& what);
bool decode_image(const Message& m, Encoding e, ImageMessage& out, std::string& what);
bool decode_compressed_image(const Message& m, Encoding e, CompressedImageMessage& out,
                             std::string& what);
// Only the header's stamp, of any message that begins with a std_msgs/Header.
bool decode_stamp(const Message& m, Encoding e, std::int64_t& stamp_ns, std::string& what);

// The image's pixels as 8-bit grey into out (width x height bytes): mono8 as it is, mono16 as
// its upper byte, colour (rgb8, bgr8, rgba8, bgra8) as its BT.601 luma, YUV 4:2:2 (yuv422 as
// UYVY, yuv422_yuy2 as YUYV) as its Y. False for other encodings (Bayer: debayer first).
bool image_to_grey(const ImageMessage& image, std::uint8_t* out, std::string& what);

}  // namespace mirrorcal::io::bag
