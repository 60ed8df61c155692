#include "recording_csv.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include <unistd.h>

#include "mirrorcal/io/files.hpp"
#include "text_io.hpp"

namespace mirrorcal::io {

namespace {

// The fields of one file's rows, with messages that name the file and the line.
class CsvRow {
 public:
  CsvRow(LineInput& input, const std::string& file, std::string& error)
      : input_(input), file_(file), error_(error) {}

  bool header(const char* expected) {
    std::string_view line;
    if (!input_.next(line)) {
      if (!input_.error().empty()) return fail_as_input();
      return fail(1, "empty file; expected the header '" + std::string(expected) + "'");
    }
    if (text::trim(line) != expected)
      return fail(input_.line_no(), "header " + text::quoted(text::trim(line)) +
                                        " is not EuRoC's '" + std::string(expected) + "'");
    return true;
  }

  // The next non-blank line split at commas into exactly n fields; false at the end (error
  // empty) or on a line with another number of fields (error set).
  bool row(std::size_t n, std::string_view* fields) {
    std::string_view line;
    do {
      if (!input_.next(line)) return input_.error().empty() ? false : fail_as_input();
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
      return fail(input_.line_no(), "expected " + std::to_string(n) +
                                        " comma-separated fields, found " + std::to_string(count) +
                                        (input_.at_end() ? " (truncated file?)" : ""));
    return true;
  }

  bool number(std::string_view field, const char* what, double& v) {
    if (!text::parse(field, v))
      return fail(std::string(what) + ": " + text::quoted(field) + " is not a number");
    if (!std::isfinite(v))
      return fail(std::string(what) + ": " + text::quoted(field) + " is not finite");
    return true;
  }

  bool integer(std::string_view field, const char* what, std::int64_t& v) {
    if (!text::parse(field, v))
      return fail(std::string(what) + ": " + text::quoted(field) + " is not an integer (int64)");
    return true;
  }

  // A timestamp that must follow the previous one (strictly, unless repeats are allowed).
  bool in_order(std::int64_t t, bool any, std::int64_t last, bool repeats_allowed) {
    if (!any || t > last || (repeats_allowed && t == last)) return true;
    return fail("timestamp " + std::to_string(t) + (t == last ? " repeats" : " goes backwards") +
                " (previous " + std::to_string(last) + ")");
  }

  bool fail(const std::string& what) { return fail(input_.line_no(), what); }
  bool fail(std::size_t line, const std::string& what) {
    error_ = file_ + ":" + std::to_string(line) + ": " + what;
    return false;
  }

 private:
  bool fail_as_input() {
    error_ = input_.error();
    return false;
  }

  LineInput& input_;
  const std::string& file_;
  std::string& error_;
};

}  // namespace

// --- LineInput ---------------------------------------------------------------------------------

LineInput::~LineInput() {
  if (fd_ >= 0) ::close(fd_);
}

bool LineInput::open(const std::string& path, std::string& error) {
  path_ = path;
  fd_ = io::open_regular_file(path, error);
  if (fd_ < 0) return false;
  buffer_.resize(kMaxLine);
  text_ = std::string_view(buffer_.data(), 0);
  eof_ = false;
  return true;
}

bool LineInput::fill() {
  if (eof_) return false;
  // The unread bytes move to the front; the rest of the buffer takes what follows them.
  const std::size_t kept = text_.size();
  std::memmove(buffer_.data(), text_.data(), kept);
  for (;;) {
    const ssize_t n = ::read(fd_, buffer_.data() + kept, buffer_.size() - kept);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      error_ = path_ + ": read error: " + std::strerror(errno);
      eof_ = true;
      return false;
    }
    text_ = std::string_view(buffer_.data(), kept + static_cast<std::size_t>(n));
    if (n == 0) eof_ = true;
    return n > 0;
  }
}

bool LineInput::next(std::string_view& line) {
  if (!error_.empty()) return false;
  std::size_t nl = text_.find('\n');
  while (nl == std::string_view::npos && !eof_) {
    if (text_.size() == buffer_.size()) {
      error_ = path_ + ":" + std::to_string(line_no_ + 1) + ": a line longer than " +
               std::to_string(kMaxLine) + " characters: not a CSV file of this recording?";
      return false;
    }
    const std::size_t searched = text_.size();
    fill();
    if (!error_.empty()) return false;
    nl = text_.find('\n', searched);
  }
  if (text_.empty()) return false;
  const std::size_t end = nl == std::string_view::npos ? text_.size() : nl;
  line = text_.substr(0, end);
  text_.remove_prefix(std::min(end + 1, text_.size()));
  ++line_no_;
  return true;
}

bool LineInput::next_chunk(std::string_view& chunk) {
  if (text_.empty() && !fill()) return false;
  chunk = text_;
  text_ = std::string_view(buffer_.data(), 0);
  return true;
}

bool LineInput::at_end() {
  // Bytes not yet read may follow in the file; this only tells a cut last line apart.
  return text_.empty() && eof_;
}

// --- the rows of each file ---------------------------------------------------------------------

bool ImuRows::header() {
  return CsvRow(input_, file_, error_).header(kImuHeader);
}

bool ImuRows::next(ImuSample& s) {
  static const char* const names[7] = {"timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z",
                                       "a_RS_S_x",  "a_RS_S_y", "a_RS_S_z"};
  CsvRow csv(input_, file_, error_);
  std::string_view f[7];
  if (!csv.row(7, f)) return false;
  double v[6];
  if (!csv.integer(f[0], names[0], s.t_ns)) return false;
  for (int j = 0; j < 6; ++j)
    if (!csv.number(f[j + 1], names[j + 1], v[j])) return false;
  s.gyro = Eigen::Vector3d(v[0], v[1], v[2]);
  s.accel = Eigen::Vector3d(v[3], v[4], v[5]);
  if (!csv.in_order(s.t_ns, any_, last_ns_, false)) return false;
  any_ = true;
  last_ns_ = s.t_ns;
  return true;
}

bool FrameRows::header() {
  return CsvRow(input_, file_, error_).header(kFramesHeader);
}

bool FrameRows::next(std::int64_t& t_ns) {
  CsvRow csv(input_, file_, error_);
  std::string_view f[2];
  if (!csv.row(2, f) || !csv.integer(f[0], "timestamp", t_ns)) return false;
  filename_ = text::trim(f[1]);
  if (filename_.empty()) return csv.fail("empty filename");
  if (!csv.in_order(t_ns, any_, last_ns_, false)) return false;
  any_ = true;
  last_ns_ = t_ns;
  return true;
}

bool FeatureRows::header() {
  return CsvRow(input_, file_, error_).header(kFeaturesHeader);
}

bool FeatureRows::next(FeatureRow& row) {
  CsvRow csv(input_, file_, error_);
  std::string_view f[4];
  if (!csv.row(4, f)) return false;
  std::int64_t id = 0;
  if (!csv.integer(f[0], "timestamp", row.t_ns) || !csv.integer(f[1], "feature_id", id) ||
      !csv.number(f[2], "u", row.marker.u) || !csv.number(f[3], "v", row.marker.v))
    return false;
  if (any_ && row.t_ns < last_ns_)
    return csv.fail("timestamp " + std::to_string(row.t_ns) + " goes backwards (previous " +
                    std::to_string(last_ns_) + ")");
  if (id < 0 || id >= markers_)
    return csv.fail("feature_id " + std::to_string(id) +
                    " is not a marker of this calibration (ids 0.." + std::to_string(markers_ - 1) +
                    ", M = " + std::to_string(markers_) + ")");
  row.marker.id = static_cast<int>(id);
  any_ = true;
  last_ns_ = row.t_ns;
  return true;
}

bool FeatureRows::fail(const std::string& what) {
  return CsvRow(input_, file_, error_).fail(what);
}

// --- FrameReader -------------------------------------------------------------------------------

FrameReader::FrameReader(LineInput& frames, const std::string& frames_csv, LineInput& features,
                         const std::string& features_csv, int markers)
    : frames_(frames, frames_csv), features_(features, features_csv, markers) {}

bool FrameReader::headers() {
  return frames_.header() && (!with_features_ || features_.header());
}

const std::string& FrameReader::error() const {
  return !frames_.error().empty() ? frames_.error() : features_.error();
}

bool FrameReader::next(ObservedFrame& frame) {
  const auto not_a_frame = [&] {
    return features_.fail("timestamp " + std::to_string(pending_.t_ns) +
                          " is not a frame of cam0/data.csv");
  };
  // The next feature row into pending_, unless one waits there; false at the end or on error.
  const auto pend = [&] {
    if (has_pending_) return true;
    if (features_done_) return false;
    has_pending_ = features_.next(pending_);
    features_done_ = !has_pending_;
    return has_pending_;
  };
  std::int64_t t = 0;
  if (!with_features_) {
    if (!frames_.next(t)) return false;
    frame.t_ns = t;
    frame.markers.clear();
    return true;
  }
  if (!frames_.next(t)) {
    // Rows left in features.csv after the last frame belong to none.
    if (frames_.error().empty() && pend()) not_a_frame();
    return false;
  }
  frame.t_ns = t;
  frame.markers.clear();
  while (pend()) {
    if (pending_.t_ns > t) break;
    if (pending_.t_ns < t) return not_a_frame();  // between this frame and the one before
    const int id = pending_.marker.id;
    if (std::any_of(frame.markers.begin(), frame.markers.end(),
                    [&](const ObservedMarker& m) { return m.id == id; }))
      return features_.fail("feature_id " + std::to_string(id) + " repeats in the frame at " +
                            std::to_string(t));
    frame.markers.push_back(pending_.marker);
    has_pending_ = false;
  }
  return features_.error().empty();
}

// --- the parsers on a text ---------------------------------------------------------------------

bool parse_imu_csv(std::string_view text, const std::string& file, std::vector<ImuSample>& out,
                   std::string& error) {
  out.clear();
  LineInput input(text);
  ImuRows rows(input, file);
  ImuSample s;
  if (rows.header())
    while (rows.next(s)) out.push_back(s);
  error = rows.error();
  return error.empty();
}

bool parse_frames_csv(std::string_view text, const std::string& file,
                      std::vector<ObservedFrame>& out, std::string& error) {
  out.clear();
  LineInput input(text);
  FrameRows rows(input, file);
  std::int64_t t = 0;
  if (rows.header())
    while (rows.next(t)) out.push_back(ObservedFrame{t, {}});
  error = rows.error();
  return error.empty();
}

bool parse_features_csv(std::string_view text, const std::string& file, int markers,
                        std::vector<ObservedFrame>& frames, std::string& error) {
  LineInput input(text);
  FeatureRows rows(input, file, markers);
  FeatureRow row;
  std::size_t frame = 0;
  if (rows.header())
    while (rows.next(row)) {
      while (frame < frames.size() && frames[frame].t_ns < row.t_ns) ++frame;
      if (frame == frames.size() || frames[frame].t_ns != row.t_ns) {
        rows.fail("timestamp " + std::to_string(row.t_ns) + " is not a frame of cam0/data.csv");
        break;
      }
      auto& seen = frames[frame].markers;
      if (std::any_of(seen.begin(), seen.end(),
                      [&](const ObservedMarker& m) { return m.id == row.marker.id; })) {
        rows.fail("feature_id " + std::to_string(row.marker.id) + " repeats in the frame at " +
                  std::to_string(row.t_ns));
        break;
      }
      seen.push_back(row.marker);
    }
  error = rows.error();
  return error.empty();
}

}  // namespace mirrorcal::io
