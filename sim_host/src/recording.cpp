// EuRoC recordings: the streaming writer, the CSV parsers and read_recording.
#include "mirrorcal/sim_host/recording.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include <fcntl.h>
#include <unistd.h>

#include "mirrorcal/sim_host/files.hpp"
#include "recording_checks.hpp"
#include "text_io.hpp"

namespace mirrorcal::sim {

namespace {

constexpr const char* kImuHeader =
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";
constexpr const char* kFramesHeader = "#timestamp [ns],filename";
constexpr const char* kFeaturesHeader = "#timestamp [ns],feature_id,u [px],v [px]";

// A CSV file's lines with their numbers, after a header that must be exactly EuRoC's.
class CsvReader {
 public:
  CsvReader(std::string_view text, const std::string& file, std::string& error)
      : text_(text), file_(file), error_(error) {}

  bool header(const char* expected) {
    std::string_view line;
    if (!next_line(line))
      return fail(1, "empty file; expected the header '" + std::string(expected) + "'");
    if (text::trim(line) != expected)
      return fail(line_no_, "header " + text::quoted(text::trim(line)) + " is not EuRoC's '" +
                                std::string(expected) + "'");
    return true;
  }

  // The next non-blank line split at commas into exactly n fields; false at the end (error empty)
  // or on a line with another number of fields (error set).
  bool row(std::size_t n, std::string_view* fields) {
    std::string_view line;
    do {
      if (!next_line(line)) return false;
    } while (text::trim(line).empty());
    std::size_t count = 0;
    for (;;) {
      const std::size_t comma = line.find(',');
      if (count < n) fields[count] = line.substr(0, comma);
      ++count;
      if (comma == std::string_view::npos) break;
      line.remove_prefix(comma + 1);
    }
    if (count != n)
      return fail(line_no_, "expected " + std::to_string(n) + " comma-separated fields, found " +
                                std::to_string(count) + (at_end() ? " (truncated file?)" : ""));
    return true;
  }

  bool number(std::string_view field, const char* what, double& v) {
    if (!text::parse(field, v))
      return fail(line_no_, std::string(what) + ": " + text::quoted(field) + " is not a number");
    if (!std::isfinite(v))
      return fail(line_no_, std::string(what) + ": " + text::quoted(field) + " is not finite");
    return true;
  }

  bool integer(std::string_view field, const char* what, std::int64_t& v) {
    if (!text::parse(field, v))
      return fail(line_no_,
                  std::string(what) + ": " + text::quoted(field) + " is not an integer (int64)");
    return true;
  }

  bool fail(std::size_t line, const std::string& what) {
    error_ = file_ + ":" + std::to_string(line) + ": " + what;
    return false;
  }
  std::size_t line_no() const { return line_no_; }
  bool failed() const { return !error_.empty(); }

 private:
  bool at_end() const { return pos_ >= text_.size(); }
  bool next_line(std::string_view& line) {
    if (at_end()) return false;
    const std::size_t nl = text_.find('\n', pos_);
    const std::size_t end = nl == std::string_view::npos ? text_.size() : nl;
    line = text_.substr(pos_, end - pos_);
    pos_ = end + 1;
    ++line_no_;
    return true;
  }

  std::string_view text_;
  const std::string& file_;
  std::string& error_;
  std::size_t pos_ = 0, line_no_ = 0;
};

}  // namespace

bool parse_imu_csv(std::string_view text, const std::string& file, std::vector<ImuSample>& out,
                   std::string& error) {
  error.clear();
  out.clear();
  CsvReader csv(text, file, error);
  if (!csv.header(kImuHeader)) return false;
  std::string_view f[7];
  static const char* const names[7] = {"timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z",
                                       "a_RS_S_x",  "a_RS_S_y", "a_RS_S_z"};
  while (csv.row(7, f)) {
    ImuSample s;
    double v[6];
    if (!csv.integer(f[0], names[0], s.t_ns)) return false;
    for (int j = 0; j < 6; ++j)
      if (!csv.number(f[j + 1], names[j + 1], v[j])) return false;
    s.gyro = Eigen::Vector3d(v[0], v[1], v[2]);
    s.accel = Eigen::Vector3d(v[3], v[4], v[5]);
    if (!out.empty() && s.t_ns <= out.back().t_ns)
      return csv.fail(csv.line_no(),
                      "timestamp " + std::to_string(s.t_ns) +
                          (s.t_ns == out.back().t_ns ? " repeats" : " goes backwards") +
                          " (previous " + std::to_string(out.back().t_ns) + ")");
    out.push_back(s);
  }
  return !csv.failed();
}

bool parse_frames_csv(std::string_view text, const std::string& file,
                      std::vector<ObservedFrame>& out, std::string& error) {
  error.clear();
  out.clear();
  CsvReader csv(text, file, error);
  if (!csv.header(kFramesHeader)) return false;
  std::string_view f[2];
  while (csv.row(2, f)) {
    ObservedFrame frame;
    if (!csv.integer(f[0], "timestamp", frame.t_ns)) return false;
    if (text::trim(f[1]).empty()) return csv.fail(csv.line_no(), "empty filename");
    if (!out.empty() && frame.t_ns <= out.back().t_ns)
      return csv.fail(csv.line_no(),
                      "timestamp " + std::to_string(frame.t_ns) +
                          (frame.t_ns == out.back().t_ns ? " repeats" : " goes backwards") +
                          " (previous " + std::to_string(out.back().t_ns) + ")");
    out.push_back(std::move(frame));
  }
  return !csv.failed();
}

bool parse_features_csv(std::string_view text, const std::string& file, int markers,
                        std::vector<ObservedFrame>& frames, std::string& error) {
  error.clear();
  CsvReader csv(text, file, error);
  if (!csv.header(kFeaturesHeader)) return false;
  std::string_view f[4];
  std::size_t frame = 0;
  bool any = false;
  std::int64_t last_t = 0;
  while (csv.row(4, f)) {
    std::int64_t t = 0, id = 0;
    double u = 0.0, v = 0.0;
    if (!csv.integer(f[0], "timestamp", t) || !csv.integer(f[1], "feature_id", id) ||
        !csv.number(f[2], "u", u) || !csv.number(f[3], "v", v))
      return false;
    if (any && t < last_t)
      return csv.fail(csv.line_no(), "timestamp " + std::to_string(t) +
                                         " goes backwards (previous " + std::to_string(last_t) +
                                         ")");
    if (id < 0 || id >= markers)
      return csv.fail(csv.line_no(), "feature_id " + std::to_string(id) +
                                         " is not a marker of this calibration (ids 0.." +
                                         std::to_string(markers - 1) +
                                         ", M = " + std::to_string(markers) + ")");
    while (frame < frames.size() && frames[frame].t_ns < t) ++frame;
    if (frame == frames.size() || frames[frame].t_ns != t)
      return csv.fail(csv.line_no(),
                      "timestamp " + std::to_string(t) + " is not a frame of cam0/data.csv");
    auto& seen = frames[frame].markers;
    if (std::any_of(seen.begin(), seen.end(), [&](const ObservedMarker& m) { return m.id == id; }))
      return csv.fail(csv.line_no(), "feature_id " + std::to_string(id) +
                                         " repeats in the frame at " + std::to_string(t));
    seen.push_back({static_cast<int>(id), u, v});
    any = true;
    last_t = t;
  }
  return !csv.failed();
}

namespace {

// FNV-1a over the bytes of each file in turn: the same data give the same fingerprint, wherever
// the recording lies.
class Fingerprint {
 public:
  void add(std::string_view bytes) {
    for (const char c : bytes) {
      hash_ ^= static_cast<unsigned char>(c);
      hash_ *= 0x100000001b3ULL;
    }
  }
  std::string hex() const {
    char s[17];
    std::snprintf(s, sizeof s, "%016llx", static_cast<unsigned long long>(hash_));
    return s;
  }

 private:
  std::uint64_t hash_ = 0xcbf29ce484222325ULL;
};

}  // namespace

bool read_recording(const std::string& dir, int markers, Recording& out, std::string& error) {
  out = Recording{};
  std::string text;
  const std::string imu_csv = dir + "/mav0/imu0/data.csv";
  const std::string frames_csv = dir + "/mav0/cam0/data.csv";
  const std::string features_csv = dir + "/mav0/cam0/features.csv";
  const std::string imu_yaml = dir + "/imu.yaml", cam_yaml = dir + "/camchain.yaml";
  const std::string priors_yaml = dir + "/mirrorcal.yaml";
  if (!files::read_file(imu_yaml, text, error) ||
      !parse_imu_yaml(text, imu_yaml, out.sensors, error))
    return false;
  if (!files::read_file(cam_yaml, text, error) ||
      !parse_camchain_yaml(text, cam_yaml, out.sensors, out.notes, error))
    return false;
  if (!files::read_file(priors_yaml, text, error) ||
      !parse_priors_yaml(text, priors_yaml, out.sensors.intrinsics, out.priors, out.notes, error))
    return false;
  const std::string truth_yaml = dir + "/truth.yaml";
  out.has_truth = std::filesystem::exists(truth_yaml);
  if (out.has_truth && (!files::read_file(truth_yaml, text, error) ||
                        !parse_truth_yaml(text, truth_yaml, out.truth, error)))
    return false;
  Fingerprint fingerprint;
  if (!files::read_file(imu_csv, text, error) || !parse_imu_csv(text, imu_csv, out.imu, error))
    return false;
  fingerprint.add(text);
  if (!files::read_file(frames_csv, text, error) ||
      !parse_frames_csv(text, frames_csv, out.frames, error))
    return false;
  fingerprint.add(text);
  if (!files::read_file(features_csv, text, error) ||
      !parse_features_csv(text, features_csv, markers, out.frames, error))
    return false;
  fingerprint.add(text);
  out.fingerprint = fingerprint.hex();

  // The filter starts at the first IMU sample and ends at the last: frames outside are skipped.
  if (out.imu.size() < 2) {
    error = imu_csv + ": " + std::to_string(out.imu.size()) +
            " IMU samples; the filter needs at least 2 (it propagates between samples)";
    return false;
  }
  // An IMU-only recording (record without a camera) says so before anything about its data.
  if (out.frames.empty()) {
    error = frames_csv + ": no frame within the IMU data; the filter needs at least one";
    return false;
  }
  const RecordingFiles named{imu_csv, frames_csv, imu_yaml};
  if (!check_imu_rate(out, named, error) || !check_frames_against_imu(out, named, error) ||
      !check_imu_units(out, named, error))
    return false;
  check_noise_densities(out, named, out.warnings);
  const std::int64_t t0 = out.imu.front().t_ns, t1 = out.imu.back().t_ns;
  const auto outside = [&](const ObservedFrame& f) { return f.t_ns < t0 || f.t_ns > t1; };
  const std::size_t before = out.frames.size();
  out.frames.erase(std::remove_if(out.frames.begin(), out.frames.end(), outside), out.frames.end());
  out.frames_outside_imu = before - out.frames.size();
  if (out.frames_outside_imu > 0)
    out.notes.push_back(frames_csv + ": " + std::to_string(out.frames_outside_imu) +
                        " frames outside the IMU data (" + std::to_string(t0) + ".." +
                        std::to_string(t1) + " ns) skipped");
  for (int id = 0; id < markers; ++id) {
    const bool seen =
        std::any_of(out.frames.begin(), out.frames.end(), [&](const ObservedFrame& f) {
          return std::any_of(f.markers.begin(), f.markers.end(),
                             [&](const ObservedMarker& m) { return m.id == id; });
        });
    if (!seen) {
      error = features_csv + ": marker " + std::to_string(id) +
              " is seen in no frame within the IMU data; the filter cannot locate it";
      return false;
    }
  }
  return true;
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
  streams_ = std::make_unique<files::OutputSet>();
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
  p = std::copy_n("pgm\n", 4, p);
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

// An 8-bit PGM through POSIX calls, which need no heap (unlike a FILE).
bool RecordingWriter::write_image(std::int64_t t_ns, const GrayImage& image) {
  if (!images_dir_) {  // created with the first image, so image-less recordings have none
    std::error_code ec;
    std::filesystem::create_directories(images_path_, ec);
    if (ec) {
      errno = 0;
      return fail("cannot create the image folder", images_path_);
    }
    images_dir_ = true;
  }
  char path[4096];
  std::snprintf(path, sizeof path, "%s/%lld.pgm", images_path_.c_str(),
                static_cast<long long>(t_ns));
  const int fd = ::open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return fail("cannot write", path);
  char header[64];
  const int h = std::snprintf(header, sizeof header, "P5\n%d %d\n255\n", image.width, image.height);
  const std::size_t n =
      static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
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
  const bool ok = write_all(header, static_cast<std::size_t>(h)) && write_all(image.pixels, n);
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
  return files::read_file(file, text, error) && parse_calibration_start(text, file, out, error);
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

}  // namespace mirrorcal::sim
