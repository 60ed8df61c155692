// A recording's CSV files read row by row, from memory (the parsers on a text) or streamed from
// the file in a buffer of fixed size (calibrate), with the same checks and messages either way.
// Internal to io.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "mirrorcal/io/recording.hpp"

namespace mirrorcal::io {

// EuRoC's headers, and ours of features.csv.
inline constexpr const char* kImuHeader =
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";
inline constexpr const char* kFramesHeader = "#timestamp [ns],filename";

// The lines of a text, or of a regular file read in chunks: memory bounded by the longest line
// allowed (kMaxLine), whatever the file's size.
class LineInput {
 public:
  static constexpr std::size_t kMaxLine = 1 << 16;
  explicit LineInput(std::string_view text) : text_(text), eof_(true) {}
  LineInput() = default;
  LineInput(const LineInput&) = delete;
  LineInput& operator=(const LineInput&) = delete;
  ~LineInput();

  // The regular file path (io::read_file's rules); false with a message naming it.
  bool open(const std::string& path, std::string& error);
  // The next line without its '\n', valid until the next call; false at the end, or on a read
  // error or a line longer than kMaxLine (error() set).
  bool next(std::string_view& line);
  // The bytes as they come instead of lines (for a fingerprint); false at the end or on error.
  bool next_chunk(std::string_view& chunk);
  // Nothing follows the last line returned (as far as read: a hint for messages).
  bool at_end();
  const std::string& error() const { return error_; }
  std::size_t line_no() const { return line_no_; }

 private:
  bool fill();  // reads more of the file after the unread bytes; false at its end or on error

  std::string_view text_;  // the unread bytes: of the text, or of buffer_
  std::vector<char> buffer_;
  std::string path_, error_;
  int fd_ = -1;
  bool eof_ = false;
  std::size_t line_no_ = 0;
};

// imu0/data.csv's samples, each checked (fields, numbers, increasing timestamps).
class ImuRows {
 public:
  ImuRows(LineInput& input, std::string file) : input_(input), file_(std::move(file)) {}
  // The header, then next() until false; error() empty at the end of the file.
  bool header();
  bool next(ImuSample& sample);
  const std::string& error() const { return error_; }

 private:
  LineInput& input_;
  std::string file_, error_;
  bool any_ = false;
  std::int64_t last_ns_ = 0;
};

// cam0/data.csv's frames, each checked (increasing timestamps, a file name), without markers.
class FrameRows {
 public:
  FrameRows(LineInput& input, std::string file) : input_(input), file_(std::move(file)) {}
  bool header();
  bool next(std::int64_t& t_ns);
  // The last row's file name (trimmed), valid until the next row is read.
  std::string_view filename() const { return filename_; }
  const std::string& error() const { return error_; }

 private:
  LineInput& input_;
  std::string file_, error_;
  std::string_view filename_;
  bool any_ = false;
  std::int64_t last_ns_ = 0;
};

// features.csv's rows, each checked (non-decreasing timestamps, ids 0..M-1).
struct FeatureRow {
  std::int64_t t_ns = 0;
  ObservedMarker marker;
};
class FeatureRows {
 public:
  FeatureRows(LineInput& input, std::string file, int markers)
      : input_(input), file_(std::move(file)), markers_(markers) {}
  bool header();
  bool next(FeatureRow& row);
  // The row just read is wrong against cam0/data.csv: sets error() with its line and returns
  // false.
  bool fail(const std::string& what);
  const std::string& error() const { return error_; }

 private:
  LineInput& input_;
  std::string file_, error_;
  int markers_;
  bool any_ = false;
  std::int64_t last_ns_ = 0;
};

// The frames of cam0/data.csv with their markers from features.csv, read side by side: each
// feature row must belong to a frame, and a marker appear once in a frame.
class FrameReader {
 public:
  FrameReader(LineInput& frames, const std::string& frames_csv, LineInput& features,
              const std::string& features_csv, int markers);
  // cam0/data.csv alone (markers from the images): every frame without markers, features unread.
  void frames_only() { with_features_ = false; }
  // The last frame's file name, valid until the next frame is read.
  std::string_view filename() const { return frames_.filename(); }
  bool headers();
  // The next frame; false at the end of cam0/data.csv (error() empty) or on bad input. frame's
  // marker list is reused, so reading allocates nothing once it holds M markers.
  bool next(ObservedFrame& frame);
  const std::string& error() const;

 private:
  FrameRows frames_;
  FeatureRows features_;
  FeatureRow pending_;  // the first feature row of a later frame, read ahead
  bool has_pending_ = false, features_done_ = false, with_features_ = true;
  std::string error_;
};

}  // namespace mirrorcal::io
