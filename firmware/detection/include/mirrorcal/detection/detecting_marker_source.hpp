// The loop's marker source on a camera: frames from a hal::FrameSource, blobs found in each and
// labelled as markers. poll() labels by brightness alone; the loop, once it has propagated the
// filter to the frame's time, relabels the frame with the filter's prediction (relabel(), through
// CalibrationLoop::set_identifier). The same code runs on the board (V4L2 frames) and in the host
// simulation (rendered frames). Nothing allocates per frame.
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>

#include "mirrorcal/detection/blink_names.hpp"
#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/marker_identifier.hpp"
#include "mirrorcal/detection/shape_bootstrap.hpp"
#include "mirrorcal/hal/frames.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::detection {

template <int M>
struct DetectionConfig {
  BlobConfig blobs{};
  IdentifierConfig<M> identify{};
  // Under loose priors, where no single frame tells the LEDs apart (identical LEDs, or a light of
  // the room as bright as one): the rig's shape fitted to reflections tracked over the first
  // seconds names the tracks (the brightness code charged where the LEDs have one), and each blob
  // is labelled by its track's name until the prediction is sharp (shape_bootstrap.hpp). prior
  // holds the priors' guesses of the markers, their sigma, the camera and the pixel noise.
  bool bootstrap_shape = false;
  RigGeometry<M> prior{};
  // With bootstrap_shape: the names an earlier look at the same frames gave its tracks
  // (ShapeBootstrap::names; none named: no_track_names), so that they label from the first frame
  // the names hold from.
  TrackNames<M> names_ahead = no_track_names<M>();
  // LEDs that blink their names (hal/blink_code.hpp), on the frames' sequence numbers: each
  // track is named by the frames it goes dark in (blink_names.hpp), in place of the bootstrap.
  hal::BlinkCode blink{};
};

struct DetectionCounters {
  std::uint64_t frames = 0;           // frames detected in
  std::uint64_t corrupt_skipped = 0;  // frames the device flagged as damaged: not used
  std::uint64_t relabelled = 0;       // frames labelled with the filter's prediction
  double detect_seconds = 0.0;        // wall time spent in detection and identification
};

// A frame's blobs as detection found them, for a later pass over the same frames to take instead
// of reading and detecting the image again (BlobReplay).
struct DetectedFrame {
  static constexpr int kMaxBlobs = 32;
  std::int64_t t_ns = 0;
  std::uint32_t sequence = 0;
  int count = 0;
  std::array<Blob, kMaxBlobs> blobs{};
};

// The detected frames of passes over one recording (the host's calibration makes several): the
// first pass that reaches the end of the stream keeps every frame's blobs, and the passes after
// it replay them, so that each image is read and detected once.
class BlobReplay {
 public:
  virtual ~BlobReplay() = default;
  // The frames a pass kept up to the end of the stream (0: none has yet).
  virtual std::size_t complete() const = 0;
  virtual void read(std::size_t k, DetectedFrame& frame) const = 0;
  // Frame k of the stream as this pass detected it (every pass counts from the first frame).
  virtual void keep(std::size_t k, const DetectedFrame& frame) = 0;
  // This pass met the end of the stream after `frames` frames, all kept.
  virtual void ended(std::size_t frames) = 0;
};

template <int M>
class DetectingMarkerSource final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  DetectingMarkerSource(hal::FrameSource& frames, const DetectionConfig<M>& config, int max_width,
                        int max_height)
      : frames_(frames),
        detector_(config.blobs, max_width, max_height),
        identifier_(identifier_config(config)),
        bootstrap_shape_(config.bootstrap_shape && !config.blink.on()),
        bootstrap_(config.prior, config.identify),
        blink_on_(config.blink.on()),
        blink_(config.blink, config.identify.max_spread_px2) {
    bootstrap_.name_ahead(config.names_ahead);
  }

  // Replays the frames replay kept, once a pass has kept them all, and keeps them until then.
  void replay_with(BlobReplay* replay) { replay_ = replay; }

  hal::SourceStatus poll(MarkerFrame<M>& frame) override {
    hal::FrameView view;
    const bool replaying = replay_ != nullptr && replay_->complete() > 0;
    const hal::SourceStatus st = replaying ? replay(view) : next_frame(view);
    if (st != hal::SourceStatus::kOk) return st;
    const auto t0 = std::chrono::steady_clock::now();
    if (!replaying) {
      blob_count_ = detector_.detect(view, blobs_.data(), static_cast<int>(blobs_.size()));
      keep(view);
    }
    if (bootstrap_shape_) bootstrap_.feed(view.t_ns, blobs_.data(), blob_count_);
    if (blink_on_) blink_.feed(view.t_ns, view.sequence, blobs_.data(), blob_count_);
    committed_ += last_;  // the previous frame's labelling is final now
    last_ = identifier_.identify(blobs_.data(), blob_count_, nullptr, frame, track_labels(),
                                 dark_marker());
    frame.t_ns = view.t_ns;
    const double seconds = seconds_since(t0);
    last_detection_ns_ = static_cast<std::int64_t>(seconds * 1e9);
    counters_.detect_seconds += seconds;
    ++counters_.frames;
    return hal::SourceStatus::kOk;
  }

  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override {
    const auto t0 = std::chrono::steady_clock::now();
    last_ = identifier_.identify(blobs_.data(), blob_count_, &prediction, frame, track_labels(),
                                 dark_marker());
    if (bootstrap_shape_) {
      std::array<int, M> blob_of_marker;
      std::array<bool, M> sharp;
      for (int i = 0; i < M; ++i) {
        blob_of_marker[std::size_t(i)] = identifier_.blob_of(i);
        sharp[std::size_t(i)] = identifier_.sharp(&prediction, i);
      }
      bootstrap_.confirm(blob_of_marker, sharp);
    }
    counters_.detect_seconds += seconds_since(t0);
    ++counters_.relabelled;
  }

  const char* error() const override { return frames_.error(); }
  // Detection's share of the last poll that delivered a frame, for the loop's timing budget.
  std::int64_t detection_ns() const override { return last_detection_ns_; }

  const DetectionCounters& counters() const { return counters_; }
  const BlobCounters& blob_counters() const { return detector_.counters(); }
  IdentifierCounters identifier_counters() const {
    IdentifierCounters c = committed_;
    c += last_;
    return c;
  }
  hal::FrameCounters frame_counters() const { return frames_.counters(); }
  // The shape's bootstrap and the tracks' names, with bootstrap_shape.
  const ShapeBootstrap<M>& bootstrap() const { return bootstrap_; }
  // The blink code's names, with DetectionConfig::blink.
  const BlinkNames<M>& blink_names() const { return blink_; }
  // The image of the last frame delivered (record --images keeps it), valid until the next poll.
  const hal::FrameView& last_frame() const { return last_view_; }
  // The blobs of the last frame (for diagnostics and tests).
  const Blob* last_blobs(int& n) const {
    n = blob_count_;
    return blobs_.data();
  }

 private:
  // The identifier told the detector's crowding distance and, with the priors, the pixel noise.
  static IdentifierConfig<M> identifier_config(const DetectionConfig<M>& config) {
    IdentifierConfig<M> identify = config.identify;
    identify.crowded_px = 2.0 * config.blobs.centroid_radius;
    if (config.bootstrap_shape) identify.pixel_sigma_px = config.prior.pixel_sigma;
    return identify;
  }

  // The next frame the device has not flagged as damaged.
  hal::SourceStatus next_frame(hal::FrameView& view) {
    for (;;) {
      const hal::SourceStatus st = frames_.poll(view);
      if (st == hal::SourceStatus::kEndOfStream && replay_ != nullptr) replay_->ended(frame_index_);
      if (st != hal::SourceStatus::kOk) return st;
      if ((view.flags & hal::kFrameCorrupt) == 0) break;
      ++counters_.corrupt_skipped;
    }
    last_view_ = view;
    return hal::SourceStatus::kOk;
  }
  void keep(const hal::FrameView& view) {
    if (replay_ != nullptr) {
      kept_.t_ns = view.t_ns;
      kept_.sequence = view.sequence;
      kept_.count = blob_count_;
      std::copy(blobs_.begin(), blobs_.begin() + blob_count_, kept_.blobs.begin());
      replay_->keep(frame_index_, kept_);
    }
    ++frame_index_;
  }
  hal::SourceStatus replay(hal::FrameView& view) {
    if (frame_index_ == replay_->complete()) return hal::SourceStatus::kEndOfStream;
    replay_->read(frame_index_++, kept_);
    view = hal::FrameView{};
    view.t_ns = kept_.t_ns;
    view.sequence = kept_.sequence;
    blob_count_ = kept_.count;
    std::copy(kept_.blobs.begin(), kept_.blobs.begin() + blob_count_, blobs_.begin());
    return hal::SourceStatus::kOk;
  }
  const int* track_labels() const {
    if (blink_on_) return blink_.blob_labels();
    return bootstrap_shape_ ? bootstrap_.blob_labels() : nullptr;
  }
  int dark_marker() const { return blink_on_ ? blink_.dark_marker() : -1; }

  static double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  hal::FrameSource& frames_;
  BlobDetector detector_;
  MarkerIdentifier<M> identifier_;
  static_assert(ShapeBootstrap<M>::kMaxBlobs == MarkerIdentifier<M>::kMaxBlobs,
                "the bootstrap names the identifier's blobs");
  bool bootstrap_shape_;
  ShapeBootstrap<M> bootstrap_;
  bool blink_on_;
  BlinkNames<M> blink_;
  std::array<Blob, MarkerIdentifier<M>::kMaxBlobs> blobs_{};
  static_assert(DetectedFrame::kMaxBlobs == MarkerIdentifier<M>::kMaxBlobs,
                "a replayed frame holds the blobs the identifier takes");
  int blob_count_ = 0;
  BlobReplay* replay_ = nullptr;
  std::size_t frame_index_ = 0;  // of this pass, from the stream's first frame
  DetectedFrame kept_{};
  hal::FrameView last_view_{};
  IdentifierCounters committed_{}, last_{};
  DetectionCounters counters_{};
  std::int64_t last_detection_ns_ = 0;
};

}  // namespace mirrorcal::detection
