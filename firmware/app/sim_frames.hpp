// mirrorcal sim --frames: the simulated rig's markers found in rendered camera frames by the
// board's detection code (blob detection, identification with the filter's prediction) instead
// of being listed, and the detection scored against what was drawn.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "mirrorcal/drivers/detecting_marker_source.hpp"
#include "mirrorcal/sim_host/frame_renderer.hpp"
#include "sim_run.hpp"

namespace mirrorcal::app {

// The detection of several runs as one: counts summed, the centroid RMS over all labelled markers,
// the maximum of the maxima, time per frame over all frames.
DetectionReport combine(const std::vector<DetectionReport>& runs);

// One line saying how detection did (sim and montecarlo print it).
void print_detection(const DetectionReport& d, hal::PixelFormat format);

// The detection settings for frames drawn with the given renderer settings: its brightness
// ratios are the identification's second cue.
drivers::DetectionConfig<kMarkers> detection_config(const sim::RenderConfig& render);

// The marker source of a run with frames: renders frame after frame and detects the markers in
// them; the loop relabels each with its prediction (give it this object with set_identifier),
// and every frame so labelled is scored against the truth it was drawn from.
class RenderedMarkers final : public hal::MarkerSource<kMarkers>,
                              public hal::MarkerRelabeler<kMarkers> {
 public:
  RenderedMarkers(const sim::Scenario& s, const sim::RenderConfig& render, std::uint64_t seed);
  hal::SourceStatus poll(MarkerFrame<kMarkers>& frame) override { return detect_.poll(frame); }
  std::int64_t detection_ns() const override { return detect_.detection_ns(); }
  void relabel(const hal::MarkerPrediction<kMarkers>& prediction,
               MarkerFrame<kMarkers>& frame) override;
  DetectionReport report() const;

 private:
  sim::RenderedFrameSource frames_;
  drivers::DetectingMarkerSource<kMarkers> detect_;
  DetectionReport report_{};
  double sum_sq_ = 0.0, sum_u_ = 0.0, sum_v_ = 0.0;
};

// The marker source of a calibration from a recording's images: the board's detection on each
// image (the default DetectionConfig, as `run` and `record` on the board use), labelled by
// brightness when polled and by the filter's prediction when the loop relabels it. On destruction
// it leaves how detection went in report, if it met at least as many frames as the one before
// (so report ends with the last pass over all the data, not a shorter stretch of it).
class ImageMarkers final : public hal::MarkerSource<kMarkers>,
                           public hal::MarkerRelabeler<kMarkers> {
 public:
  ImageMarkers(std::unique_ptr<hal::FrameSource> frames, int width, int height,
               DetectionReport* report);
  ~ImageMarkers() override;
  hal::SourceStatus poll(MarkerFrame<kMarkers>& frame) override;
  void relabel(const hal::MarkerPrediction<kMarkers>& prediction,
               MarkerFrame<kMarkers>& frame) override;
  const char* error() const override { return detect_.error(); }
  std::int64_t detection_ns() const override { return detect_.detection_ns(); }

 private:
  std::unique_ptr<hal::FrameSource> frames_;
  drivers::DetectingMarkerSource<kMarkers> detect_;
  DetectionReport* report_;
  std::uint64_t frames_seen_ = 0, labelled_ = 0;
  double read_seconds_ = 0.0;
};

}  // namespace mirrorcal::app
