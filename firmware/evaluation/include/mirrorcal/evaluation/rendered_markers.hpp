// mirrorcal sim --frames: the simulated rig's markers found in rendered camera frames by the
// board's detection code (blob detection, identification with the filter's prediction) instead
// of being listed, and the detection scored against what was drawn.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/sim_host/frame_renderer.hpp"

namespace mirrorcal::evaluation {

using calibration::DetectionReport;
using calibration::kMarkers;

// The detection of several runs as one: counts summed, the centroid RMS over all labelled markers,
// the maximum of the maxima, time per frame over all frames.
DetectionReport combine(const std::vector<DetectionReport>& runs);

// One line saying how detection did (sim and montecarlo print it).
void print_detection(const DetectionReport& d, hal::PixelFormat format);

// The detection settings for frames drawn with the given renderer settings: its brightness
// ratios are the identification's second cue.
detection::DetectionConfig<kMarkers> detection_config(const sim::RenderConfig& render);

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
  detection::DetectingMarkerSource<kMarkers> detect_;
  DetectionReport report_{};
  double sum_sq_ = 0.0, sum_u_ = 0.0, sum_v_ = 0.0;
};

}  // namespace mirrorcal::evaluation
