// The markers of a recording's images, found by the board's detection: what `calibrate` runs on
// when a recording holds images instead of (or beside) features.csv.
#pragma once

#include <cstdint>
#include <memory>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"

namespace mirrorcal::calibration {

// The marker source of a calibration from a recording's images: the board's detection on each
// image (the default DetectionConfig, as `run` and `record` on the board use), labelled by
// brightness when polled and by the filter's prediction when the loop relabels it. On destruction
// it leaves how detection went in report, if it met at least as many frames as the one before
// (so report ends with the last pass over all the data, not a shorter stretch of it).
template <int M>
class ImageMarkers final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
               DetectionReport* report);
  ~ImageMarkers() override;
  hal::SourceStatus poll(MarkerFrame<M>& frame) override;
  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override;
  const char* error() const override { return detect_.error(); }
  std::int64_t detection_ns() const override { return detect_.detection_ns(); }

 private:
  std::unique_ptr<hal::FrameSource> frames_;
  detection::DetectingMarkerSource<M> detect_;
  DetectionReport* report_;
  std::uint64_t frames_seen_ = 0, labelled_ = 0;
  double read_seconds_ = 0.0;
};
// Compiled in image_markers.cpp for every built M.
#define MIRRORCAL_EXTERN_IMAGE_MARKERS_(M) extern template class ImageMarkers<M>;
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_EXTERN_IMAGE_MARKERS_)
#undef MIRRORCAL_EXTERN_IMAGE_MARKERS_

}  // namespace mirrorcal::calibration
