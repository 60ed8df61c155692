#include "bag_messages.hpp"

#include <cstring>

#include "mirrorcal/io/images.hpp"

namespace mirrorcal::io::bag {

namespace {

// A message's fields in order. ROS 1 packs them little-endian without padding; CDR (ROS 2's, by
// the OMG's rules) begins with a 4-byte encapsulation header and aligns each primitive to its size,
// counted from the end of that header. A message too short for its fields reads as !ok().
class Fields {
 public:
  Fields(const Message& m, Encoding e)
      : p_(m.data), end_(m.data + m.size), cdr_(e == Encoding::kCdr) {
    if (!cdr_) {
      origin_ = p_;
      return;
    }
    // 00 01: CDR little-endian (what every ROS 2 middleware writes); 00 00 is big-endian.
    if (m.size < 4 || m.data[0] != 0 || m.data[1] != 1) {
      ok_ = false;
      big_endian_cdr_ = m.size >= 4 && m.data[0] == 0 && m.data[1] == 0;
      return;
    }
    p_ += 4;
    origin_ = p_;
  }
  template <typename T>
  T get() {
    align(sizeof(T));
    T v{};
    if (!take(sizeof(T))) return v;
    std::memcpy(&v, p_ - sizeof(T), sizeof(T));
    return v;
  }
  // A string: ROS 1's length and bytes; CDR's length counts a closing NUL, dropped here.
  std::string_view string() {
    const auto n = get<std::uint32_t>();
    if (!take(n)) return {};
    std::string_view s(reinterpret_cast<const char*>(p_ - n), n);
    if (cdr_ && !s.empty() && s.back() == '\0') s.remove_suffix(1);
    return s;
  }
  // A uint8[] (sequence): its length, then its bytes.
  const std::uint8_t* bytes(std::size_t& n) {
    n = get<std::uint32_t>();
    if (!take(n)) return nullptr;
    return p_ - n;
  }
  void skip_doubles(int n) {
    for (int k = 0; k < n; ++k) get<double>();
  }
  // std_msgs/Header: ROS 1's seq, stamp (u32 s, u32 ns), frame_id; ROS 2's stamp (i32 s, u32 ns),
  // frame_id.
  std::int64_t header_stamp_ns() {
    if (!cdr_) get<std::uint32_t>();  // seq
    const std::int64_t sec =
        cdr_ ? std::int64_t{get<std::int32_t>()} : std::int64_t{get<std::uint32_t>()};
    const auto nsec = get<std::uint32_t>();
    string();  // frame_id
    return sec * 1000000000 + nsec;
  }
  bool ok() const { return ok_; }
  // What went wrong, for a message that did not read.
  const char* problem() const {
    return big_endian_cdr_
               ? "big-endian CDR, which mirrorcal does not read"
               : (cdr_ ? "shorter than its fields, or not CDR" : "shorter than its fields");
  }

 private:
  void align(std::size_t n) {
    if (!cdr_) return;
    const auto at = static_cast<std::size_t>(p_ - origin_);
    take((n - at % n) % n);
  }
  bool take(std::size_t n) {
    if (!ok_ || static_cast<std::size_t>(end_ - p_) < n) {
      ok_ = false;
      p_ = end_;
      return false;
    }
    p_ += n;
    return true;
  }

  const std::uint8_t* p_;
  const std::uint8_t* end_;
  const std::uint8_t* origin_ = nullptr;
  bool cdr_;
  bool ok_ = true, big_endian_cdr_ = false;
};

bool done(const Fields& f, const char* type, std::string& what) {
  if (f.ok()) return true;
  what = std::string("a ") + type + " message that does not read: " + f.problem();
  return false;
}

}  // namespace

MessageType message_type(const Topic& topic) {
  const std::string& t = topic.type;
  if (t == "sensor_msgs/Imu" || t == "sensor_msgs/msg/Imu") return MessageType::kImu;
  if (t == "sensor_msgs/Image" || t == "sensor_msgs/msg/Image") return MessageType::kImage;
  if (t == "sensor_msgs/CompressedImage" || t == "sensor_msgs/msg/CompressedImage")
    return MessageType::kCompressedImage;
  return MessageType::kOther;
}

bool decode_imu(const Message& m, Encoding e, ImuSample& out, std::string& what) {
  Fields f(m, e);
  out.t_ns = f.header_stamp_ns();
  f.skip_doubles(4 + 9);  // orientation and its covariance
  out.gyro = {f.get<double>(), f.get<double>(), f.get<double>()};
  f.skip_doubles(9);
  out.accel = {f.get<double>(), f.get<double>(), f.get<double>()};
  f.skip_doubles(9);
  return done(f, "sensor_msgs/Imu", what);
}

bool decode_image(const Message& m, Encoding e, ImageMessage& out, std::string& what) {
  Fields f(m, e);
  out.stamp_ns = f.header_stamp_ns();
  out.height = f.get<std::uint32_t>();
  out.width = f.get<std::uint32_t>();
  out.encoding = f.string();
  out.big_endian = f.get<std::uint8_t>() != 0;
  out.step = f.get<std::uint32_t>();
  out.data = f.bytes(out.size);
  if (!done(f, "sensor_msgs/Image", what)) return false;
  if (std::uint64_t{out.step} * out.height > out.size) {
    what = "an image of " + std::to_string(out.height) + " rows of " + std::to_string(out.step) +
           " bytes holds only " + std::to_string(out.size) + " bytes";
    return false;
  }
  return true;
}

bool decode_compressed_image(const Message& m, Encoding e, CompressedImageMessage& out,
                             std::string& what) {
  Fields f(m, e);
  out.stamp_ns = f.header_stamp_ns();
  out.format = f.string();
  out.data = f.bytes(out.size);
  return done(f, "sensor_msgs/CompressedImage", what);
}

bool decode_stamp(const Message& m, Encoding e, std::int64_t& stamp_ns, std::string& what) {
  Fields f(m, e);
  stamp_ns = f.header_stamp_ns();
  return done(f, "std_msgs/Header", what);
}

namespace {

// Bytes per pixel of the encodings read, and where a pixel's grey comes from.
struct PixelLayout {
  std::uint32_t bytes = 0;
  enum { kGrey8, kGrey16, kRgb, kBgr, kYuv } kind = kGrey8;
  std::uint32_t y_at = 0;  // the Y byte of a YUV 4:2:2 pixel pair's first pixel
};

bool layout_of(std::string_view encoding, bool big_endian, PixelLayout& l) {
  if (encoding == "mono8" || encoding == "8UC1")
    l = {1, PixelLayout::kGrey8, 0};
  else if (encoding == "mono16" || encoding == "16UC1")
    l = {2, PixelLayout::kGrey16, big_endian ? 0u : 1u};  // the upper byte
  else if (encoding == "rgb8")
    l = {3, PixelLayout::kRgb, 0};
  else if (encoding == "rgba8")
    l = {4, PixelLayout::kRgb, 0};
  else if (encoding == "bgr8" || encoding == "8UC3")
    l = {3, PixelLayout::kBgr, 0};
  else if (encoding == "bgra8" || encoding == "8UC4")
    l = {4, PixelLayout::kBgr, 0};
  else if (encoding == "yuv422" || encoding == "uyvy")
    l = {2, PixelLayout::kYuv, 1};
  else if (encoding == "yuv422_yuy2" || encoding == "yuyv")
    l = {2, PixelLayout::kYuv, 0};
  else
    return false;
  return true;
}

}  // namespace

bool image_to_grey(const ImageMessage& image, std::uint8_t* out, std::string& what) {
  PixelLayout l;
  if (!layout_of(image.encoding, image.big_endian, l)) {
    what = "image encoding '" + std::string(image.encoding) + "' is not read" +
           (image.encoding.substr(0, 5) == "bayer" ? " (debayer the images, or record mono8)"
                                                   : " (mono8, mono16, rgb8, bgr8, rgba8, bgra8, "
                                                     "yuv422 and yuv422_yuy2 are)");
    return false;
  }
  if (std::uint64_t{image.width} * l.bytes > image.step) {
    what = "its rows of " + std::to_string(image.step) + " bytes are shorter than " +
           std::to_string(image.width) + " pixels of " + std::string(image.encoding);
    return false;
  }
  for (std::uint32_t y = 0; y < image.height; ++y) {
    const std::uint8_t* row = image.data + std::size_t(y) * image.step;
    std::uint8_t* o = out + std::size_t(y) * image.width;
    for (std::uint32_t x = 0; x < image.width; ++x) {
      const std::uint8_t* p = row + std::size_t(x) * l.bytes;
      switch (l.kind) {
        case PixelLayout::kGrey8:
        case PixelLayout::kGrey16:
        case PixelLayout::kYuv:  // every pixel of a pair has its own Y, y_at into its 2 bytes
          o[x] = p[l.y_at];
          break;
        case PixelLayout::kRgb:
          o[x] = bt601_luma(p[0], p[1], p[2]);
          break;
        case PixelLayout::kBgr:
          o[x] = bt601_luma(p[2], p[1], p[0]);
          break;
      }
    }
  }
  return true;
}

}  // namespace mirrorcal::io::bag
