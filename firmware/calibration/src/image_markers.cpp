#include "mirrorcal/calibration/image_markers.hpp"

#include <chrono>

namespace mirrorcal::calibration {

ImageMarkers::ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
                           DetectionReport* report)
    : frames_(std::move(frames)),
      detect_(*frames_, detection::DetectionConfig<kMarkers>{}, width, height),
      report_(report) {}

ImageMarkers::~ImageMarkers() {
  if (report_ == nullptr || frames_seen_ < report_->frames) return;
  DetectionReport r;
  r.frames = frames_seen_;
  r.markers_labelled = labelled_;
  const double detect = detect_.counters().detect_seconds;
  const double n = frames_seen_ > 0 ? static_cast<double>(frames_seen_) : 1.0;
  r.ms_per_frame = 1e3 * detect / n;
  r.read_ms_per_frame = 1e3 * read_seconds_ / n;
  const detection::IdentifierCounters& id = detect_.identifier_counters();
  r.dropped_in_doubt = id.ambiguous + id.crossing + id.refused;
  r.unlabelled_blobs = id.unassigned;
  *report_ = r;
}

hal::SourceStatus ImageMarkers::poll(MarkerFrame<kMarkers>& frame) {
  const double detecting = detect_.counters().detect_seconds;
  const auto t0 = std::chrono::steady_clock::now();
  const hal::SourceStatus st = detect_.poll(frame);
  // The poll's time less detection's share of it: reading the image.
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() -
                   (detect_.counters().detect_seconds - detecting);
  if (st == hal::SourceStatus::kOk) ++frames_seen_;
  return st;
}

void ImageMarkers::relabel(const hal::MarkerPrediction<kMarkers>& prediction,
                           MarkerFrame<kMarkers>& frame) {
  detect_.relabel(prediction, frame);
  for (const bool seen : frame.seen) labelled_ += seen ? 1 : 0;
}

}  // namespace mirrorcal::calibration
