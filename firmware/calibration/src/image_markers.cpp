#include "mirrorcal/calibration/image_markers.hpp"

#include <chrono>

namespace mirrorcal::calibration {

template <int M>
ImageMarkers<M>::ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
                              DetectionReport* report, const sim::MarkerLeds& leds,
                              ImageBlobs* blobs)
    : frames_(std::move(frames)),
      detect_(*frames_, marker_detection_config<M>(leds), width, height),
      report_(report),
      blobs_(blobs),
      replayed_(blobs != nullptr && blobs->complete() > 0) {
  detect_.replay_with(blobs);
}

template <int M>
ImageMarkers<M>::~ImageMarkers() {
  if (report_ == nullptr || frames_seen_ < report_->frames) return;
  DetectionReport r;
  r.frames = frames_seen_;
  r.markers_labelled = labelled_;
  double detect = detect_.counters().detect_seconds, read = read_seconds_;
  // Reading and detecting as the pass that read the images took them (a replay skips both).
  if (blobs_ != nullptr && !replayed_ && blobs_->complete() > 0) {
    blobs_->read_seconds = read;
    blobs_->detect_seconds = detect;
  } else if (replayed_) {
    read = blobs_->read_seconds;
    detect = blobs_->detect_seconds;
  }
  const double n = frames_seen_ > 0 ? static_cast<double>(frames_seen_) : 1.0;
  r.ms_per_frame = 1e3 * detect / n;
  r.read_ms_per_frame = 1e3 * read / n;
  const detection::IdentifierCounters& id = detect_.identifier_counters();
  r.dropped_in_doubt = id.ambiguous + id.crossing + id.refused;
  r.unlabelled_blobs = id.unassigned;
  *report_ = r;
}

template <int M>
hal::SourceStatus ImageMarkers<M>::poll(MarkerFrame<M>& frame) {
  const double detecting = detect_.counters().detect_seconds;
  const auto t0 = std::chrono::steady_clock::now();
  const hal::SourceStatus st = detect_.poll(frame);
  // The poll's time less detection's share of it: reading the image.
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() -
                   (detect_.counters().detect_seconds - detecting);
  if (st == hal::SourceStatus::kOk) ++frames_seen_;
  return st;
}

template <int M>
void ImageMarkers<M>::relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) {
  detect_.relabel(prediction, frame);
  for (const bool seen : frame.seen) labelled_ += seen ? 1 : 0;
}

#define MIRRORCAL_IMAGE_MARKERS_(M) template class ImageMarkers<M>;
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_IMAGE_MARKERS_)
#undef MIRRORCAL_IMAGE_MARKERS_

}  // namespace mirrorcal::calibration
