// EuRoC recordings: the streaming writer, the CSV parsers and read_recording.
#include "mirrorcal/io/recording.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>

#include <fcntl.h>
#include <unistd.h>

#include "mirrorcal/io/bags.hpp"
#include "mirrorcal/io/files.hpp"
#include "recording_checks.hpp"
#include "recording_csv.hpp"
#include "text_io.hpp"

namespace mirrorcal::io {

namespace {

// The paths of a recording's CSV files.
struct CsvFiles {
  std::string imu_csv, frames_csv, features_csv;
};

CsvFiles csv_files(const std::string& dir) {
  return {dir + "/mav0/imu0/data.csv", dir + "/mav0/cam0/data.csv",
          dir + "/mav0/cam0/features.csv"};
}

// The fingerprint of the CSV files' bytes, read in chunks.
bool fingerprint_of(const CsvFiles& f, std::string& hex, std::string& error) {
  Fingerprint fingerprint;
  for (const std::string* path : {&f.imu_csv, &f.frames_csv, &f.features_csv}) {
    if (path->empty()) continue;  // markers from the images: no features.csv
    LineInput input;
    if (!input.open(*path, error)) return false;
    std::string_view chunk;
    while (input.next_chunk(chunk)) fingerprint.add(chunk);
    if (!input.error().empty()) {
      error = input.error();
      return false;
    }
  }
  hex = fingerprint.hex();
  return true;
}

// One pass over the CSV files: every row checked, the statistics of the checks gathered, each
// sample and frame handed to keep_* (read_recording holds them).
bool gather_stats(const CsvFiles& f, int markers, RecordingStats& stats,
                  const std::function<void(const ImuSample&)>& keep_imu,
                  const std::function<void(const ObservedFrame&)>& keep_frame, std::string& error) {
  StatsGatherer gatherer(markers);
  {
    LineInput input;
    if (!input.open(f.imu_csv, error)) return false;
    ImuRows rows(input, f.imu_csv);
    ImuSample s;
    if (rows.header())
      while (rows.next(s)) {
        gatherer.add(s);
        if (keep_imu) keep_imu(s);
      }
    if (!rows.error().empty()) {
      error = rows.error();
      return false;
    }
  }
  LineInput frames, features;
  const bool with_features = !f.features_csv.empty();
  if (!frames.open(f.frames_csv, error) || (with_features && !features.open(f.features_csv, error)))
    return false;
  FrameReader reader(frames, f.frames_csv, features, f.features_csv, markers);
  if (!with_features) reader.frames_only();
  ObservedFrame frame;
  if (reader.headers())
    while (reader.next(frame)) {
      gatherer.add(frame);
      if (keep_frame) keep_frame(frame);
    }
  if (!reader.error().empty()) {
    error = reader.error();
    return false;
  }
  stats = gatherer.finish();
  return true;
}

// A recording that `record` did not complete (killed while writing it) is refused, saying so: its
// temporary folder, or a folder it never renamed into place (of a --two-stage recording too).
bool check_not_cut(const std::string& dir, std::vector<std::string>& notes, std::string& error) {
  if (io::is_staging_folder(dir)) {
    error = dir +
            ": a recording cut off before it was complete (record was stopped while writing "
            "it): record it again";
    return false;
  }
  std::error_code ec;
  const std::filesystem::path parent = std::filesystem::path(dir).parent_path();
  for (const std::string& target : {dir, parent.empty() ? std::string() : parent.string()}) {
    const std::vector<std::string> cut =
        target.empty() ? std::vector<std::string>{} : io::cut_folders(target);
    if (cut.empty()) continue;
    if (!std::filesystem::exists(dir, ec)) {
      error = dir + ": no recording: record was stopped before it completed it (what it wrote " +
              "lies in " + cut.back() + "): record it again";
      return false;
    }
    notes.push_back(target + ": a later record into it was stopped before it completed (" +
                    cut.back() + "); this is the recording before it");
    break;
  }
  return true;
}

// The YAML files of dir, the statistics of its streams, and the input checks; keep_* receive the
// streams (read_recording).
bool read_checked(const std::string& dir, int markers, Recording& out,
                  const std::function<void(const ImuSample&)>& keep_imu,
                  const std::function<void(const ObservedFrame&)>& keep_frame, std::string& error,
                  bool from_images = false) {
  out = Recording{};
  out.from_images = from_images;
  if (!check_not_cut(dir, out.notes, error)) return false;
  CsvFiles csv = csv_files(dir);
  if (from_images) {
    if (!has_images(dir)) {
      error = dir +
              "/mav0/cam0/data: no such folder: the recording has no images to find the "
              "markers in";
      return false;
    }
    csv.features_csv.clear();
  }
  if (!read_descriptions(dir, out, error) ||
      !gather_stats(csv, markers, out.stats, keep_imu, keep_frame, error) ||
      !fingerprint_of(csv, out.fingerprint, error))
    return false;
  return check_recording(out, {csv.imu_csv, csv.frames_csv, dir + "/imu.yaml", csv.features_csv},
                         markers, error);
}

}  // namespace

bool read_descriptions(const std::string& dir, Recording& out, std::string& error) {
  std::string text;
  const std::string imu_yaml = dir + "/imu.yaml", cam_yaml = dir + "/camchain.yaml";
  const std::string priors_yaml = dir + "/mirrorcal.yaml";
  if (!io::read_file(imu_yaml, text, error) ||
      !parse_imu_yaml(text, imu_yaml, out.sensors, out.notes, error))
    return false;
  if (!io::read_file(cam_yaml, text, error) ||
      !parse_camchain_yaml(text, cam_yaml, out.sensors, out.notes, error))
    return false;
  if (!io::read_file(priors_yaml, text, error) ||
      !parse_priors_yaml(text, priors_yaml, out.sensors.intrinsics, out.priors, out.notes, error))
    return false;
  const std::string truth_yaml = dir + "/truth.yaml";
  out.has_truth = std::filesystem::exists(truth_yaml);
  return !out.has_truth || (io::read_file(truth_yaml, text, error) &&
                            parse_truth_yaml(text, truth_yaml, out.truth, error));
}

bool check_recording(Recording& out, const RecordingFiles& named, int markers, std::string& error) {
  const RecordingStats& st = out.stats;
  // The filter starts at the first IMU sample and ends at the last: frames outside are skipped.
  if (st.imu_samples < 2) {
    error = named.imu_csv + ": " + std::to_string(st.imu_samples) +
            " IMU samples; the filter needs at least 2 (it propagates between samples)";
    return false;
  }
  // An IMU-only recording (record without a camera) says so before anything about its data.
  if (st.frames_listed == 0) {
    error = named.frames_csv + ": no frame within the IMU data; the filter needs at least one";
    return false;
  }
  if (!check_imu_rate(out, named, error) || !check_frames_against_imu(out, named, error) ||
      !check_imu_units(out, named, error))
    return false;
  check_noise_densities(out, named, out.warnings);
  out.frames_outside_imu = st.frames_listed - st.frames;
  if (out.frames_outside_imu > 0)
    out.notes.push_back(named.frames_csv + ": " + std::to_string(out.frames_outside_imu) +
                        " frames outside the IMU data (" + std::to_string(st.imu_first_ns) + ".." +
                        std::to_string(st.imu_last_ns) + " ns) skipped");
  for (int id = 0; id < markers && !out.from_images; ++id)
    if (!st.marker_seen[static_cast<std::size_t>(id)]) {
      error = named.features_csv + ": marker " + std::to_string(id) +
              " is seen in no frame within the IMU data; the filter cannot locate it";
      return false;
    }
  return true;
}

bool read_recording(const std::string& dir, int markers, Recording& out, std::string& error) {
  // The frames within the IMU data only; its span is known once all of it has been read.
  std::vector<ImuSample> imu;
  std::vector<ObservedFrame> frames;
  if (!read_checked(
          dir, markers, out, [&](const ImuSample& s) { imu.push_back(s); },
          [&](const ObservedFrame& f) { frames.push_back(f); }, error))
    return false;
  const auto outside = [&](const ObservedFrame& f) {
    return f.t_ns < out.stats.imu_first_ns || f.t_ns > out.stats.imu_last_ns;
  };
  frames.erase(std::remove_if(frames.begin(), frames.end(), outside), frames.end());
  out.imu = std::move(imu);
  out.frames = std::move(frames);
  return true;
}

// --- FileStreams --------------------------------------------------------------------------

namespace {

class FileImuSource final : public hal::ImuSource {
 public:
  FileImuSource(const std::string& path, std::string& first_error)
      : rows_(input_, path), first_error_(first_error) {
    std::string error;
    if (!input_.open(path, error) || !rows_.header()) fail(error);
  }
  hal::SourceStatus next(ImuSample& sample) override {
    if (!error_.empty()) return hal::SourceStatus::kError;
    if (rows_.next(sample)) return hal::SourceStatus::kOk;
    if (rows_.error().empty()) return hal::SourceStatus::kEndOfStream;
    fail(rows_.error());
    return hal::SourceStatus::kError;
  }
  const char* error() const override { return error_.c_str(); }

 private:
  void fail(const std::string& error) {
    error_ = !error.empty() ? error : rows_.error();
    if (first_error_.empty()) first_error_ = error_ + " (the file changed while calibrating?)";
  }
  LineInput input_;
  ImuRows rows_;
  std::string error_;
  std::string& first_error_;
};

class FileFrameStream final : public FrameStream {
 public:
  FileFrameStream(const CsvFiles& f, int markers, std::int64_t first_ns, std::int64_t last_ns,
                  std::string& first_error)
      : reader_(frames_, f.frames_csv, features_, f.features_csv, markers),
        first_ns_(first_ns),
        last_ns_(last_ns),
        first_error_(first_error) {
    std::string error;
    const bool with_features = !f.features_csv.empty();  // none: the markers are in the images
    if (!with_features) reader_.frames_only();
    if (!frames_.open(f.frames_csv, error) ||
        (with_features && !features_.open(f.features_csv, error)) || !reader_.headers())
      fail(error);
  }
  hal::SourceStatus next(ObservedFrame& frame) override {
    while (error_.empty()) {
      if (!reader_.next(frame)) {
        if (reader_.error().empty()) return hal::SourceStatus::kEndOfStream;
        fail(reader_.error());
        break;
      }
      if (frame.t_ns < first_ns_) continue;
      if (frame.t_ns > last_ns_) return hal::SourceStatus::kEndOfStream;
      return hal::SourceStatus::kOk;
    }
    return hal::SourceStatus::kError;
  }

 private:
  void fail(const std::string& error) {
    error_ = !error.empty() ? error : reader_.error();
    if (first_error_.empty()) first_error_ = error_ + " (the file changed while calibrating?)";
  }
  LineInput frames_, features_;
  FrameReader reader_;
  std::int64_t first_ns_, last_ns_;
  std::string error_;
  std::string& first_error_;
};

// The images of cam0/data.csv's frames within the IMU data, read one per frame into buffers
// allocated when opened. An image that cannot be read (or has another size than camchain.yaml's)
// is skipped and named in the log; the frames after it go on.
class FileImageSource final : public hal::FrameSource {
 public:
  FileImageSource(const CsvFiles& f, const std::string& images_dir, int width, int height,
                  std::int64_t first_ns, std::int64_t last_ns, ImageLog& log,
                  std::string& first_error)
      : reader_(frames_, f.frames_csv, no_features_, f.features_csv, 0),
        images_(width, height),
        images_dir_(images_dir),
        width_(width),
        height_(height),
        first_ns_(first_ns),
        last_ns_(last_ns),
        log_(log),
        first_error_(first_error) {
    reader_.frames_only();
    frame_.markers.reserve(1);
    std::string error;
    if (!frames_.open(f.frames_csv, error) || !reader_.headers()) fail(error);
  }
  ~FileImageSource() override {
    if (unreadable_ > log_.unreadable) log_.unreadable = unreadable_;
  }
  hal::SourceStatus poll(hal::FrameView& view) override {
    while (error_.empty()) {
      if (!reader_.next(frame_)) {
        if (reader_.error().empty()) return hal::SourceStatus::kEndOfStream;
        fail(reader_.error());
        break;
      }
      if (frame_.t_ns < first_ns_) continue;
      if (frame_.t_ns > last_ns_) return hal::SourceStatus::kEndOfStream;
      const std::string_view name = reader_.filename();
      const int n = std::snprintf(path_, sizeof path_, "%s/%.*s", images_dir_.c_str(),
                                  static_cast<int>(name.size()), name.data());
      GrayImage image;
      if (n < 0 || std::size_t(n) >= sizeof path_) {
        unreadable(path_, "path too long");
        continue;
      }
      if (!images_.read(path_, image)) {
        unreadable(images_.error(), nullptr);
        continue;
      }
      if (image.width != width_ || image.height != height_) {
        char what[96];
        std::snprintf(what, sizeof what, "%dx%d pixels; camchain.yaml's camera has %dx%d",
                      image.width, image.height, width_, height_);
        unreadable(path_, what);
        continue;
      }
      view.format = hal::PixelFormat::kGrey;
      view.width = image.width;
      view.height = image.height;
      view.bytes_per_line = image.width;
      view.data = image.pixels;
      view.bytes = std::size_t(image.width) * std::size_t(image.height);
      view.t_ns = frame_.t_ns;
      view.sequence = sequence_++;
      view.flags = 0;
      ++counters_.frames;
      return hal::SourceStatus::kOk;
    }
    return hal::SourceStatus::kError;
  }
  const char* error() const override { return error_.c_str(); }
  hal::FrameCounters counters() const override { return counters_; }

 private:
  // One image skipped: counted, and its message kept if it is among the first (each once).
  void unreadable(const char* message, const char* what) {
    ++unreadable_;
    char text[512];
    // Truncated to fit: a path's end and the reason are what matters, and both fit in practice.
    if (what != nullptr)
      std::snprintf(text, sizeof text, "%.380s: %.120s", message, what);
    else
      std::snprintf(text, sizeof text, "%.511s", message);
    log_.keep(text);
  }
  void fail(const std::string& error) {
    error_ = !error.empty() ? error : reader_.error();
    if (first_error_.empty()) first_error_ = error_ + " (the file changed while calibrating?)";
  }
  LineInput frames_, no_features_;
  FrameReader reader_;
  ImageReader images_;
  std::string images_dir_;
  int width_, height_;
  std::int64_t first_ns_, last_ns_;
  ImageLog& log_;
  std::string& first_error_;
  std::string error_;
  ObservedFrame frame_;
  char path_[4096] = "";
  std::uint32_t sequence_ = 0;
  std::uint64_t unreadable_ = 0;
  hal::FrameCounters counters_{};
};

// The streams read from the files again for each pass.
class FileStreams final : public RecordingStreams {
 public:
  // Frames before first_ns or after last_ns (the IMU data's span) are skipped. With images_dir,
  // the images of width x height pixels there are the frames' markers' source.
  FileStreams(CsvFiles files, int markers, std::int64_t first_ns, std::int64_t last_ns,
              std::string images_dir = {}, int width = 0, int height = 0)
      : files_(std::move(files)),
        markers_(markers),
        first_ns_(first_ns),
        last_ns_(last_ns),
        images_dir_(std::move(images_dir)),
        width_(width),
        height_(height) {}
  std::unique_ptr<hal::FrameSource> open_images() const override {
    if (images_dir_.empty()) return nullptr;
    return std::make_unique<FileImageSource>(files_, images_dir_, width_, height_, first_ns_,
                                             last_ns_, *log_, *error_);
  }
  const ImageLog* image_log() const override { return images_dir_.empty() ? nullptr : log_.get(); }
  std::unique_ptr<hal::ImuSource> open_imu() const override {
    return std::make_unique<FileImuSource>(files_.imu_csv, *error_);
  }
  std::unique_ptr<FrameStream> open_frames() const override {
    return std::make_unique<FileFrameStream>(files_, markers_, first_ns_, last_ns_, *error_);
  }
  const std::string& error() const override { return *error_; }

 private:
  CsvFiles files_;
  int markers_;
  std::int64_t first_ns_, last_ns_;
  std::string images_dir_;
  int width_, height_;
  std::unique_ptr<std::string> error_ = std::make_unique<std::string>();  // the sources write it
  std::unique_ptr<ImageLog> log_ = std::make_unique<ImageLog>();          // the image sources too
};

}  // namespace

void ImageLog::keep(const char* text) {
  std::array<char, 512> m{};
  std::snprintf(m.data(), m.size(), "%s", text);
  for (int k = 0; k < kept; ++k)
    if (messages[std::size_t(k)] == m) return;
  if (kept < kKept) messages[std::size_t(kept++)] = m;
}

bool recording_marker_count(const std::string& dir, int& markers, std::string& error) {
  const std::string cam_yaml = dir + "/camchain.yaml", priors_yaml = dir + "/mirrorcal.yaml";
  std::string text;
  SensorInfo sensors;
  RecordingPriors priors;
  std::vector<std::string> notes;
  if (!io::read_file(cam_yaml, text, error) ||
      !parse_camchain_yaml(text, cam_yaml, sensors, notes, error) ||
      !io::read_file(priors_yaml, text, error) ||
      !parse_priors_yaml(text, priors_yaml, sensors.intrinsics, priors, notes, error))
    return false;
  markers = static_cast<int>(priors.features_c.size());
  return true;
}

bool open_recording(const std::string& dir, int markers, Recording& out, std::string& error,
                    bool from_images) {
  if (!read_checked(dir, markers, out, {}, {}, error, from_images)) return false;
  CsvFiles csv = csv_files(dir);
  if (!from_images) {
    out.streams = std::make_shared<const FileStreams>(csv, markers, out.stats.imu_first_ns,
                                                      out.stats.imu_last_ns);
    return true;
  }
  csv.features_csv.clear();
  out.streams = std::make_shared<const FileStreams>(csv, markers, out.stats.imu_first_ns,
                                                    out.stats.imu_last_ns, dir + "/mav0/cam0/data",
                                                    out.sensors.width, out.sensors.height);
  return true;
}

bool has_features_csv(const std::string& dir) {
  std::error_code ec;
  return std::filesystem::exists(csv_files(dir).features_csv, ec);
}

bool has_images(const std::string& dir) {
  std::error_code ec;
  return std::filesystem::is_directory(dir + "/mav0/cam0/data", ec);
}

bool is_bag(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    return std::filesystem::exists(path + "/metadata.yaml", ec);
  const std::string ext = std::filesystem::path(path).extension().string();
  return ext == ".bag" || ext == ".mcap" || ext == ".db3";
}

std::string bag_sensors_dir(const std::string& path, const BagOptions& options) {
  if (!options.sensors_dir.empty()) return options.sensors_dir;
  std::error_code ec;
  // A ROS 2 bag folder may hold them itself; otherwise they lie beside the bag.
  if (std::filesystem::is_directory(path, ec) &&
      std::filesystem::exists(path + "/camchain.yaml", ec))
    return path;
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

// --- RecordingWriter ---------------------------------------------------------------------------

struct RecordingWriter::File {
  std::string path;
  std::FILE* f = nullptr;  // a temporary file of streams_, until close()
  std::vector<char> buffer;
};

namespace {

constexpr std::size_t kLine = 256;  // longest line we format: 7 numbers of at most 24 characters

// Appends v and a separator to a fixed buffer; no allocation.
template <typename T>
char* put(char* p, char* end, T v, char sep) {
  p = std::to_chars(p, end - 1, v).ptr;  // kLine leaves room: to_chars never fails here
  *p = sep;
  return p + 1;
}

}  // namespace

RecordingWriter::RecordingWriter() = default;
RecordingWriter::~RecordingWriter() = default;

bool RecordingWriter::fail(const char* what, const std::string& path) {
  if (error_.empty())
    error_ = path + ": " + what + (errno != 0 ? std::string(": ") + std::strerror(errno) : "");
  return false;
}

bool RecordingWriter::open(const std::string& dir, std::string& error) {
  dir_ = dir;
  images_path_ = dir + "/mav0/cam0/data";
  error_.clear();
  any_imu_ = any_frame_ = images_dir_ = false;
  std::error_code ec;
  for (const char* sub : {"/mav0/imu0", "/mav0/cam0"}) {
    std::filesystem::create_directories(dir + sub, ec);
    if (ec) {
      error = dir + sub + ": cannot create: " + ec.message();
      return false;
    }
  }
  streams_ = std::make_unique<io::OutputSet>();
  const auto make = [&](const std::string& path, const char* header, std::unique_ptr<File>& file) {
    file = std::make_unique<File>();
    file->path = path;
    file->f = streams_->add(path, error_);
    if (file->f == nullptr) return false;
    file->buffer.resize(1 << 16);
    std::setvbuf(file->f, file->buffer.data(), _IOFBF, file->buffer.size());
    std::fprintf(file->f, "%s\n", header);
    return true;
  };
  if (!make(dir + "/mav0/imu0/data.csv", kImuHeader, imu_) ||
      !make(dir + "/mav0/cam0/data.csv", kFramesHeader, frames_) ||
      !make(dir + "/mav0/cam0/features.csv", kFeaturesHeader, features_)) {
    error = error_;
    return false;
  }
  return true;
}

bool RecordingWriter::add_imu(const ImuSample& s) {
  if (!imu_ || imu_->f == nullptr) return fail("not open", dir_);
  if (any_imu_ && s.t_ns <= last_imu_ns_) {
    errno = 0;
    return fail("IMU timestamps must increase", imu_->path);
  }
  char line[kLine];
  char* const end = line + kLine;
  char* p = put(line, end, s.t_ns, ',');
  for (int j = 0; j < 3; ++j) p = put(p, end, s.gyro(j), ',');
  for (int j = 0; j < 3; ++j) p = put(p, end, s.accel(j), j == 2 ? '\n' : ',');
  std::fwrite(line, 1, static_cast<std::size_t>(p - line), imu_->f);
  last_imu_ns_ = s.t_ns;
  any_imu_ = true;
  return true;
}

bool RecordingWriter::add_frame(const ObservedFrame& frame, const GrayImage* image) {
  if (!begin_frame(frame.t_ns, image)) return false;
  for (const ObservedMarker& m : frame.markers) add_feature(frame.t_ns, m.id, m.u, m.v);
  return true;
}

bool RecordingWriter::begin_frame(std::int64_t t_ns, const GrayImage* image) {
  if (!frames_ || frames_->f == nullptr) return fail("not open", dir_);
  if (any_frame_ && t_ns <= last_frame_ns_) {
    errno = 0;
    return fail("frame timestamps must increase", frames_->path);
  }
  char line[kLine];
  char* const end = line + kLine;
  char* p = put(line, end, t_ns, ',');
  p = put(p, end, t_ns, '.');
  p = std::copy_n("png\n", 4, p);
  std::fwrite(line, 1, static_cast<std::size_t>(p - line), frames_->f);
  last_frame_ns_ = t_ns;
  any_frame_ = true;
  return image == nullptr || write_image(t_ns, *image);
}

void RecordingWriter::add_feature(std::int64_t t_ns, int id, double u, double v) {
  char line[kLine];
  char* const end = line + kLine;
  char* p = put(line, end, t_ns, ',');
  p = put(p, end, static_cast<std::int64_t>(id), ',');
  p = put(p, end, u, ',');
  p = put(p, end, v, '\n');
  std::fwrite(line, 1, static_cast<std::size_t>(p - line), features_->f);
}

// An 8-bit grey PNG through POSIX calls, which need no heap (unlike a FILE).
bool RecordingWriter::write_image(std::int64_t t_ns, const GrayImage& image) {
  if (!images_dir_) {  // created with the first image, so image-less recordings have none
    std::error_code ec;
    std::filesystem::create_directories(images_path_, ec);
    if (ec) {
      errno = 0;
      return fail("cannot create the image folder", images_path_);
    }
    images_dir_ = true;
    png_ = std::make_unique<PngWriter>(image.width, image.height);
  }
  char path[4096];
  std::snprintf(path, sizeof path, "%s/%lld.png", images_path_.c_str(),
                static_cast<long long>(t_ns));
  std::size_t n = 0;
  const std::uint8_t* png = png_->encode(image, n);
  if (png == nullptr) {
    errno = 0;
    return fail(png_->error(), path);
  }
  const int fd = ::open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return fail("cannot write", path);
  const auto write_all = [fd](const void* data, std::size_t size) {
    const char* c = static_cast<const char*>(data);
    while (size > 0) {
      const ssize_t w = ::write(fd, c, size);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) return false;
      c += w;
      size -= static_cast<std::size_t>(w);
    }
    return true;
  };
  const bool ok = write_all(png, n);
  if (::close(fd) != 0 || !ok) return fail("error writing", path);
  return true;
}

bool RecordingWriter::close(std::string& error) {
  for (auto* file : {&imu_, &frames_, &features_})
    if (*file) (*file)->f = nullptr;
  // The three CSV files replace those of an earlier recording only all together and complete.
  if (streams_ && error_.empty()) streams_->commit(error_);
  streams_.reset();
  error = error_;
  return error_.empty();
}

namespace {

std::string result_file(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_directory(path, ec) ? path + "/mirrorcal-result.yaml" : path;
}

}  // namespace

bool read_calibration_result(const std::string& path, CalibrationStart& out, std::string& error) {
  const std::string file = result_file(path);
  std::string text;
  return io::read_file(file, text, error) && parse_calibration_start(text, file, out, error);
}

bool read_calibration_start(const std::string& path, int markers, CalibrationStart& out,
                            std::string& error) {
  if (!read_calibration_result(path, out, error)) return false;
  if (out.features_c.size() != static_cast<std::size_t>(markers)) {
    error = result_file(path) + ": lists " + std::to_string(out.features_c.size()) +
            " markers; this build calibrates M = " + std::to_string(markers);
    return false;
  }
  return true;
}

}  // namespace mirrorcal::io
