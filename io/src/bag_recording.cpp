// A bag as a recording: its two topics checked, one pass over them for the statistics and the
// input checks, then streams that read them again for each pass of the calibration.
#include <turbojpeg.h>

#include <cstring>
#include <filesystem>
#include <limits>

#include "bag_containers.hpp"
#include "bag_messages.hpp"
#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/files.hpp"
#include "recording_checks.hpp"

namespace mirrorcal::io {

namespace {

// The topics a calibration reads, found in the bag.
struct BagTopics {
  bag::Topic imu, camera;
  bool compressed = false;  // the camera's messages are sensor_msgs/CompressedImage
};

// Where in the bag a message lies, for messages: a .db3 file's row, another file's byte.
std::string where(const bag::Message& m, const bag::Topic& topic) {
  const std::string file = m.file;
  const bool sqlite = file.size() > 4 && file.compare(file.size() - 4, 4, ".db3") == 0;
  return file + ": topic " + topic.name + ", the message " + (sqlite ? "in row " : "at byte ") +
         std::to_string(m.offset) + ": ";
}

std::string topic_list(const bag::Bag& b) {
  std::string s;
  for (const bag::Topic& t : b.topics())
    s += "\n  " + t.name + " (" + t.type + ", " + std::to_string(t.messages) + " messages)";
  return s.empty() ? " none" : s;
}

// A topic of the bag by name, of one of the types wanted, in an encoding that is read.
const bag::Topic* find_topic(const bag::Bag& b, const std::string& name, const char* named_by,
                             std::initializer_list<bag::MessageType> types, const char* type_names,
                             std::string& error) {
  const bag::Topic* t = b.topic(name);
  if (t == nullptr) {
    error =
        b.path() + ": no topic " + name + " (" + named_by + "). The bag's topics:" + topic_list(b);
    return nullptr;
  }
  if (std::find(types.begin(), types.end(), bag::message_type(*t)) == types.end()) {
    error = b.path() + ": topic " + name + " carries " + t->type + ", not " + type_names;
    return nullptr;
  }
  if (t->encoding == bag::Encoding::kOther) {
    error = b.path() + ": topic " + name + "'s messages are encoded as '" + t->encoding_name +
            "'; mirrorcal reads ROS 1's and ROS 2's (ros1, cdr)";
    return nullptr;
  }
  return t;
}

bool find_topics(const bag::Bag& b, const SensorInfo& sensors, const BagOptions& o, BagTopics& out,
                 std::string& error) {
  const bool imu_named = !o.imu_topic.empty(), camera_named = !o.camera_topic.empty();
  const bag::Topic* imu =
      find_topic(b, imu_named ? o.imu_topic : sensors.imu_rostopic,
                 imu_named ? "--imu-topic" : "imu.yaml's rostopic; --imu-topic names another",
                 {bag::MessageType::kImu}, "sensor_msgs/Imu", error);
  if (imu == nullptr) return false;
  std::string camera_name = camera_named ? o.camera_topic : sensors.rostopic;
  // image_transport's compressed images of the camera's topic, when only they were recorded.
  if (!camera_named && b.topic(camera_name) == nullptr && b.topic(camera_name + "/compressed"))
    camera_name += "/compressed";
  const bag::Topic* camera =
      find_topic(b, camera_name,
                 camera_named ? "--camera-topic"
                              : "camchain.yaml's cam0 rostopic; --camera-topic names another",
                 {bag::MessageType::kImage, bag::MessageType::kCompressedImage},
                 "sensor_msgs/Image or CompressedImage", error);
  if (camera == nullptr) return false;
  out.imu = *imu;
  out.camera = *camera;
  out.compressed = bag::message_type(*camera) == bag::MessageType::kCompressedImage;
  return true;
}

// A stream's stamps must increase, as the filter takes them; the error names both.
bool in_order(std::int64_t previous, std::int64_t stamp, const bag::Message& m,
              const bag::Topic& topic, std::string& error) {
  if (stamp > previous) return true;
  error = where(m, topic) + "its header's stamp " + std::to_string(stamp) +
          " ns does not come after the one before it, " + std::to_string(previous) + " ns";
  return false;
}

// An IMU sample as the record files keep it.
struct ImuRecord {
  std::int64_t t_ns;
  double gyro[3], accel[3];
};

// What the first pass keeps on disk for the others: the IMU's samples and the frames' stamps, so
// that a pass reads the bag again only for the images (a chunk holds both, and decompressing it
// is most of reading it).
struct BagRecords {
  io::RecordFile imu{sizeof(ImuRecord), "the bag's IMU samples"};
  io::RecordFile stamps{sizeof(std::int64_t), "the bag's frame stamps"};
};

// One pass over both topics: every message decoded and checked, the statistics gathered, the
// samples and stamps kept, and the fingerprint of their values (the same whatever container holds
// them; a folder's is of its CSV files).
bool gather_stats(const bag::Bag& b, const BagTopics& t, int markers, Recording& out,
                  BagRecords& kept, std::string& error) {
  StatsGatherer gatherer(markers);
  Fingerprint fingerprint;
  std::string what;
  bag::Message m;
  hal::SourceStatus s;
  std::int64_t last = std::numeric_limits<std::int64_t>::min();
  const auto imu = b.messages(t.imu);
  ImuSample sample;
  while ((s = imu->next(m)) == hal::SourceStatus::kOk) {
    if (!bag::decode_imu(m, t.imu.encoding, sample, what)) {
      error = where(m, t.imu) + what;
      return false;
    }
    if (!in_order(last, sample.t_ns, m, t.imu, error)) return false;
    last = sample.t_ns;
    gatherer.add(sample);
    ImuRecord r{sample.t_ns,
                {sample.gyro.x(), sample.gyro.y(), sample.gyro.z()},
                {sample.accel.x(), sample.accel.y(), sample.accel.z()}};
    kept.imu.append(&r);
    fingerprint.add({reinterpret_cast<const char*>(&r), sizeof r});
  }
  if (s == hal::SourceStatus::kError) {
    error = imu->error();
    return false;
  }
  last = std::numeric_limits<std::int64_t>::min();
  const auto camera = b.messages(t.camera);
  ObservedFrame frame;
  while ((s = camera->next(m)) == hal::SourceStatus::kOk) {
    if (!bag::decode_stamp(m, t.camera.encoding, frame.t_ns, what)) {
      error = where(m, t.camera) + what;
      return false;
    }
    if (!in_order(last, frame.t_ns, m, t.camera, error)) return false;
    last = frame.t_ns;
    gatherer.add(frame);
    kept.stamps.append(&frame.t_ns);
    fingerprint.add({reinterpret_cast<const char*>(&frame.t_ns), sizeof frame.t_ns});
  }
  if (s == hal::SourceStatus::kError) {
    error = camera->error();
    return false;
  }
  out.stats = gatherer.finish();
  out.fingerprint = fingerprint.hex();
  return true;
}

// The first error any pass's source met, for RecordingStreams::error().
void keep_first(std::string& first, const std::string& error) {
  if (first.empty()) first = error + " (the bag changed while calibrating?)";
}

// The IMU's samples as the first pass kept them.
class BagImuSource final : public hal::ImuSource {
 public:
  explicit BagImuSource(const io::RecordFile& samples) : samples_(samples) {}
  hal::SourceStatus next(ImuSample& sample) override {
    if (next_ == samples_.size()) return hal::SourceStatus::kEndOfStream;
    ImuRecord r;
    samples_.read(next_++, &r);
    sample.t_ns = r.t_ns;
    sample.gyro = {r.gyro[0], r.gyro[1], r.gyro[2]};
    sample.accel = {r.accel[0], r.accel[1], r.accel[2]};
    return hal::SourceStatus::kOk;
  }

 private:
  const io::RecordFile& samples_;
  std::size_t next_ = 0;
};

// The frames' stamps within [first_ns, last_ns] (the IMU data's span), as the first pass kept
// them.
class BagFrameStream final : public FrameStream {
 public:
  BagFrameStream(const io::RecordFile& stamps, std::int64_t first_ns, std::int64_t last_ns)
      : stamps_(stamps), first_ns_(first_ns), last_ns_(last_ns) {}
  hal::SourceStatus next(ObservedFrame& frame) override {
    frame.markers.clear();
    while (next_ < stamps_.size()) {
      stamps_.read(next_++, &frame.t_ns);
      if (frame.t_ns < first_ns_) continue;
      return frame.t_ns > last_ns_ ? hal::SourceStatus::kEndOfStream : hal::SourceStatus::kOk;
    }
    return hal::SourceStatus::kEndOfStream;
  }

 private:
  const io::RecordFile& stamps_;
  std::int64_t first_ns_, last_ns_;
  std::size_t next_ = 0;
};

// The camera's messages within [first_ns, last_ns] (the IMU data's span), by their stamps.
class CameraMessages {
 public:
  CameraMessages(const bag::Bag& b, const bag::Topic& topic, std::int64_t first_ns,
                 std::int64_t last_ns)
      : topic_(topic), messages_(b.messages(topic)), first_ns_(first_ns), last_ns_(last_ns) {}
  // kOk with the next message and its stamp; kError with error set.
  hal::SourceStatus next(bag::Message& m, std::int64_t& stamp_ns, std::string& error) {
    for (;;) {
      const hal::SourceStatus s = messages_->next(m);
      if (s == hal::SourceStatus::kError) error = messages_->error();
      if (s != hal::SourceStatus::kOk) return s;
      std::string what;
      if (!bag::decode_stamp(m, topic_.encoding, stamp_ns, what)) {
        error = where(m, topic_) + what;
        return hal::SourceStatus::kError;
      }
      if (stamp_ns < first_ns_) continue;
      return stamp_ns > last_ns_ ? hal::SourceStatus::kEndOfStream : hal::SourceStatus::kOk;
    }
  }
  const bag::Topic& topic() const { return topic_; }

 private:
  bag::Topic topic_;
  std::unique_ptr<bag::MessageStream> messages_;
  std::int64_t first_ns_, last_ns_;
};

// The camera's images as grey frames of camchain.yaml's size, into buffers allocated when opened.
// An image that cannot be read, or of another size, is skipped and named in the log (as a
// recording folder's are); the frames after it go on.
class BagImageSource final : public hal::FrameSource {
 public:
  BagImageSource(CameraMessages messages, bool compressed, int width, int height, ImageLog& log,
                 std::string& first_error)
      : messages_(std::move(messages)),
        compressed_(compressed),
        width_(width),
        height_(height),
        pixels_(std::size_t(width) * std::size_t(height)),
        png_(width, height),
        log_(log),
        first_error_(first_error) {}
  ~BagImageSource() override {
    if (jpeg_ != nullptr) tjDestroy(jpeg_);
    if (unreadable_ > log_.unreadable) log_.unreadable = unreadable_;
  }
  hal::SourceStatus poll(hal::FrameView& view) override {
    for (;;) {
      bag::Message m;
      std::int64_t stamp_ns = 0;
      std::string error;
      const hal::SourceStatus s = messages_.next(m, stamp_ns, error);
      if (s == hal::SourceStatus::kError) {
        error_ = error;
        keep_first(first_error_, error);
      }
      if (s != hal::SourceStatus::kOk) return s;
      std::string what;
      if (!(compressed_ ? decompress(m, what) : convert(m, what))) {
        unreadable(where(m, messages_.topic()) + what);
        continue;
      }
      view.format = hal::PixelFormat::kGrey;
      view.width = width_;
      view.height = height_;
      view.bytes_per_line = width_;
      view.data = image_;
      view.bytes = pixels_.size();
      view.t_ns = stamp_ns;
      view.sequence = sequence_++;
      view.flags = 0;
      ++counters_.frames;
      return s;
    }
  }
  const char* error() const override { return error_.c_str(); }
  hal::FrameCounters counters() const override { return counters_; }

 private:
  bool size_is(std::uint32_t width, std::uint32_t height, std::string& what) const {
    if (int(width) == width_ && int(height) == height_) return true;
    what = std::to_string(width) + "x" + std::to_string(height) +
           " pixels; camchain.yaml's camera has " + std::to_string(width_) + "x" +
           std::to_string(height_);
    return false;
  }
  bool convert(const bag::Message& m, std::string& what) {
    bag::ImageMessage image;
    if (!bag::decode_image(m, messages_.topic().encoding, image, what) ||
        !size_is(image.width, image.height, what) ||
        !bag::image_to_grey(image, pixels_.data(), what))
      return false;
    image_ = pixels_.data();
    return true;
  }
  bool decompress(const bag::Message& m, std::string& what) {
    bag::CompressedImageMessage c;
    if (!bag::decode_compressed_image(m, messages_.topic().encoding, c, what)) return false;
    if (c.size >= 3 && c.data[0] == 0xff && c.data[1] == 0xd8 && c.data[2] == 0xff)
      return decompress_jpeg(c, what);
    GrayImage image;
    if (!png_.decode(c.data, c.size, "the image", image)) {
      what = png_.error();
      return false;
    }
    if (!size_is(std::uint32_t(image.width), std::uint32_t(image.height), what)) return false;
    image_ = image.pixels;
    return true;
  }
  bool decompress_jpeg(const bag::CompressedImageMessage& c, std::string& what) {
    if (jpeg_ == nullptr) jpeg_ = tjInitDecompress();
    int width = 0, height = 0, subsampling = 0, colorspace = 0;
    auto* data = const_cast<unsigned char*>(c.data);
    const auto size = static_cast<unsigned long>(c.size);
    if (jpeg_ == nullptr ||
        tjDecompressHeader3(jpeg_, data, size, &width, &height, &subsampling, &colorspace) != 0) {
      what = std::string("a JPEG image that does not read: ") + tjGetErrorStr2(jpeg_);
      return false;
    }
    if (!size_is(std::uint32_t(width), std::uint32_t(height), what)) return false;
    if (tjDecompress2(jpeg_, data, size, pixels_.data(), width_, width_, height_, TJPF_GRAY, 0) !=
        0) {
      what = std::string("a JPEG image that does not read: ") + tjGetErrorStr2(jpeg_);
      return false;
    }
    image_ = pixels_.data();
    return true;
  }
  // One image skipped: counted, and its message kept if it is among the first.
  void unreadable(const std::string& message) {
    ++unreadable_;
    log_.keep(message.c_str());
  }

  CameraMessages messages_;
  bool compressed_;
  int width_, height_;
  std::vector<std::uint8_t> pixels_;
  const std::uint8_t* image_ = nullptr;
  ImageReader png_;
  tjhandle jpeg_ = nullptr;
  ImageLog& log_;
  std::string& first_error_;
  std::string error_;
  std::uint32_t sequence_ = 0;
  std::uint64_t unreadable_ = 0;
  hal::FrameCounters counters_{};
};

class BagStreams final : public RecordingStreams {
 public:
  BagStreams(std::unique_ptr<bag::Bag> b, BagTopics topics, std::unique_ptr<BagRecords> records,
             std::int64_t first_ns, std::int64_t last_ns, int width, int height)
      : bag_(std::move(b)),
        topics_(std::move(topics)),
        records_(std::move(records)),
        first_ns_(first_ns),
        last_ns_(last_ns),
        width_(width),
        height_(height) {}
  std::unique_ptr<hal::ImuSource> open_imu() const override {
    return std::make_unique<BagImuSource>(records_->imu);
  }
  std::unique_ptr<FrameStream> open_frames() const override {
    return std::make_unique<BagFrameStream>(records_->stamps, first_ns_, last_ns_);
  }
  std::unique_ptr<hal::FrameSource> open_images() const override {
    return std::make_unique<BagImageSource>(camera(), topics_.compressed, width_, height_, *log_,
                                            *error_);
  }
  const ImageLog* image_log() const override { return log_.get(); }
  const std::string& error() const override { return *error_; }

 private:
  CameraMessages camera() const { return {*bag_, topics_.camera, first_ns_, last_ns_}; }

  std::unique_ptr<bag::Bag> bag_;
  BagTopics topics_;
  std::unique_ptr<BagRecords> records_;
  std::int64_t first_ns_, last_ns_;
  int width_, height_;
  std::unique_ptr<std::string> error_ = std::make_unique<std::string>();  // the sources write it
  std::unique_ptr<ImageLog> log_ = std::make_unique<ImageLog>();          // the image sources too
};

}  // namespace

bool open_bag_recording(const std::string& path, const BagOptions& options, int markers,
                        Recording& out, std::string& error) {
  out = Recording{};
  out.from_images = true;
  const std::string sensors = bag_sensors_dir(path, options);
  if (!read_descriptions(sensors, out, error)) return false;
  std::unique_ptr<bag::Bag> b = bag::Bag::open(path, error);
  BagTopics topics;
  auto records = std::make_unique<BagRecords>();
  if (!b || !find_topics(*b, out.sensors, options, topics, error) ||
      !gather_stats(*b, topics, markers, out, *records, error))
    return false;
  const std::string imu = path + " (topic " + topics.imu.name + ")";
  const std::string camera = path + " (topic " + topics.camera.name + ")";
  if (!check_recording(out, {imu, camera, sensors + "/imu.yaml", camera}, markers, error))
    return false;
  out.streams = std::make_shared<const BagStreams>(
      std::move(b), std::move(topics), std::move(records), out.stats.imu_first_ns,
      out.stats.imu_last_ns, out.sensors.width, out.sensors.height);
  return true;
}

}  // namespace mirrorcal::io
