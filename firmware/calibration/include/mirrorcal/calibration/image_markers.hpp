// The markers of a recording's images, found by the board's detection: what `calibrate` runs on
// when a recording holds images instead of (or beside) features.csv.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/io/files.hpp"

namespace mirrorcal::calibration {

// The detection of the markers whose LEDs are described by leds (mirrorcal.yaml's keys): by their
// brightness code (the default 1 : 1.5 : 2.25 ..., or led_brightness), and by their blink code
// where they blink their names (blink_period). `calibrate` from images, `run` and `record` use it.
template <int M>
detection::DetectionConfig<M> marker_detection_config(const io::MarkerLeds& leds) {
  detection::DetectionConfig<M> c;
  if (leds.brightness.size() == static_cast<std::size_t>(M))
    for (int i = 0; i < M; ++i)
      c.identify.brightness[static_cast<std::size_t>(i)] =
          leds.brightness[static_cast<std::size_t>(i)];
  c.blink.period = leds.blink_period;
  return c;
}

// The LEDs' names by the rig's shape (detection/shape_bootstrap.hpp), for LEDs that do not blink
// theirs: what the shape is fitted with (the priors' guesses of the markers, their sigma, the
// camera, the pixel noise), the track each name went to in a look at the first frames
// (track_of_label[i]: the track named i; -1: none named), the spans of frames the names hold
// over (ShapeBootstrap's TrackNames::spans) and the shape fitted, by name. The
// brightness code names the LEDs with the shape where it has one; the priors' guesses cannot
// always tell identical LEDs apart: the LED named i is then another than the one the guess of
// marker i was for, and marker i's estimate is that LED's.
struct LedNaming {
  std::vector<Eigen::Vector3d> markers_c;
  double marker_sigma_m = 0.0;
  Pinhole<double> camera{};
  double pixel_sigma = 1.0;
  std::vector<int> track_of_label;
  std::vector<detection::NamedSpan> name_spans;
  std::vector<Eigen::Vector3d> shape_c;
};

// Looks at a recording's images from the first until the rig's shape names the reflections'
// tracks (or they end), as every pass will track them; geometry: the markers' guesses (the
// priors', or an earlier calibration's) and their sigma. The names found, none if the shape never
// fitted.
template <int M>
LedNaming name_leds_by_shape(hal::FrameSource& frames, const io::MarkerLeds& leds,
                             const detection::RigGeometry<M>& geometry, int width, int height);

// The marker source of a calibration from a recording's images: the board's detection on each
// image (marker_detection_config, as `run` and `record` on the board use), labelled by its cues
// when polled and by the filter's prediction too when the loop relabels it. On destruction
// it leaves how detection went in report, if it met at least as many frames as the one before
// (so report ends with the last pass over all the data, not a shorter stretch of it).
// The blobs of a recording's images, detected once for all the passes of its calibration (each
// pass would read and detect every image again): fixed-size records in a temporary file (a frame
// takes 1.6 KB of disk, not memory), and the time the pass that detected them took.
class ImageBlobs final : public detection::BlobReplay {
 public:
  std::size_t complete() const override { return complete_; }
  void read(std::size_t k, detection::DetectedFrame& frame) const override {
    frames_.read(k, &frame);
  }
  void keep(std::size_t k, const detection::DetectedFrame& frame) override {
    frames_.write(k, &frame);
  }
  void ended(std::size_t frames) override { complete_ = frames; }
  // Reading and detecting over the pass that kept the frames (s), which the report gives.
  double read_seconds = 0.0, detect_seconds = 0.0;

 private:
  io::RecordFile frames_{sizeof(detection::DetectedFrame), "the images' blobs"};
  std::size_t complete_ = 0;
};

template <int M>
class ImageMarkers final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  // blobs: where the passes keep and replay the detected frames (nullptr: every pass detects).
  // naming: the LEDs' names from a look at the same images (none: by the other cues).
  ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
               DetectionReport* report, const io::MarkerLeds& leds = {},
               ImageBlobs* blobs = nullptr, const LedNaming* naming = nullptr);
  ~ImageMarkers() override;
  hal::SourceStatus poll(MarkerFrame<M>& frame) override;
  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override;
  const char* error() const override { return detect_.error(); }
  std::int64_t detection_ns() const override { return detect_.detection_ns(); }

 private:
  std::unique_ptr<hal::FrameSource> frames_;
  detection::DetectingMarkerSource<M> detect_;
  DetectionReport* report_;
  ImageBlobs* blobs_;
  bool replayed_;  // the frames came from blobs_, not from the images
  std::uint64_t frames_seen_ = 0, labelled_ = 0;
  double read_seconds_ = 0.0;
};
// Compiled in image_markers.cpp for every built M.
#define MIRRORCAL_EXTERN_IMAGE_MARKERS_(M)                                                  \
  extern template class ImageMarkers<M>;                                                    \
  extern template LedNaming name_leds_by_shape<M>(hal::FrameSource&, const io::MarkerLeds&, \
                                                  const detection::RigGeometry<M>&, int, int);
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_EXTERN_IMAGE_MARKERS_)
#undef MIRRORCAL_EXTERN_IMAGE_MARKERS_

}  // namespace mirrorcal::calibration
