// mirrorcal sim --frames: the simulated rig's markers found in rendered camera frames by the
// board's detection code (blob detection, identification with the filter's prediction) instead
// of being listed, and the detection scored against what was drawn.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "mirrorcal/calibration/run.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"

namespace mirrorcal::evaluation {

using calibration::DetectionReport;

// The detection of several runs as one: counts summed, the centroid RMS over all labelled markers,
// the maximum of the maxima, time per frame over all frames.
DetectionReport combine(const std::vector<DetectionReport>& runs);

// One line saying how detection did (sim and montecarlo print it).
void print_detection(const DetectionReport& d, hal::PixelFormat format);

// The detection settings for frames drawn with the given renderer settings: its brightness
// ratios are the identification's second cue, and the rig's shape bootstrapped from the priors'
// geometry (prior; detection/shape_bootstrap.hpp) names the LEDs with them (alone where they are
// all equal: identical LEDs).
template <int M>
detection::DetectionConfig<M> detection_config(const sim::RenderConfig& render,
                                               const detection::RigGeometry<M>& prior = {});

using detection::no_track_names;
using detection::TrackNames;

// The marker source of a run with frames: renders frame after frame and detects the markers in
// them; the loop relabels each with its prediction (give it this object with set_identifier),
// and every frame so labelled is scored against the truth it was drawn from.
template <int M>
class RenderedMarkers final : public hal::MarkerSource<M>, public hal::MarkerRelabeler<M> {
 public:
  // names_ahead: the tracks' names from an earlier look at the same frames, and naming the LED
  // each name went to there (naming(), which the labels are scored against).
  RenderedMarkers(const sim::Scenario& s, const sim::RenderConfig& render,
                  const detection::RigGeometry<M>& prior, std::uint64_t seed,
                  const TrackNames<M>& names_ahead = no_track_names<M>(),
                  const std::array<int, M>* naming = nullptr);
  hal::SourceStatus poll(MarkerFrame<M>& frame) override;
  std::int64_t detection_ns() const override { return detect_.detection_ns(); }
  void relabel(const hal::MarkerPrediction<M>& prediction, MarkerFrame<M>& frame) override;
  DetectionReport report() const;
  // Identical LEDs: the marker each name stands for, naming()[i] the true id of the LED the
  // bootstrap named i (the priors' guesses cannot always tell identical LEDs apart, so the names
  // may be a permutation of the truth's); the identity until the names are given. named(): given.
  const std::array<int, M>& naming() const { return naming_; }
  bool named() const { return named_; }
  const TrackNames<M>& track_names() const { return detect_.bootstrap().names(); }

 private:
  void record_naming();

  sim::RenderedFrameSource frames_;
  detection::DetectingMarkerSource<M> detect_;
  DetectionReport report_{};
  double sum_sq_ = 0.0, sum_u_ = 0.0, sum_v_ = 0.0;
  std::array<int, M> naming_{};
  bool named_ = false;
};
// Compiled in rendered_markers.cpp for every built M.
#define MIRRORCAL_EXTERN_RENDERED_MARKERS_(M) extern template class RenderedMarkers<M>;
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_EXTERN_RENDERED_MARKERS_)
#undef MIRRORCAL_EXTERN_RENDERED_MARKERS_

}  // namespace mirrorcal::evaluation
