#include "sim_frames.hpp"

#include <algorithm>
#include <cmath>

namespace mirrorcal::app {

drivers::DetectionConfig<kMarkers> detection_config(const sim::RenderConfig& render) {
  drivers::DetectionConfig<kMarkers> c;
  for (int i = 0; i < kMarkers; ++i)
    c.identify.brightness[static_cast<std::size_t>(i)] =
        render.brightness[static_cast<std::size_t>(i) % render.brightness.size()];
  return c;
}

RenderedMarkers::RenderedMarkers(const sim::Scenario& s, const sim::RenderConfig& render,
                                 std::uint64_t seed)
    : frames_(s, render, seed),
      detect_(frames_, detection_config(render), s.truth.width, s.truth.height) {}

void RenderedMarkers::relabel(const hal::MarkerPrediction<kMarkers>& prediction,
                              MarkerFrame<kMarkers>& frame) {
  detect_.relabel(prediction, frame);
  // The loop holds one frame at a time, so the renderer's last frame is this one.
  const sim::RenderedTruth& truth = frames_.truth();
  ++report_.frames;
  for (int i = 0; i < kMarkers; ++i) {
    const auto ii = static_cast<std::size_t>(i);
    if (truth.visible[ii]) ++report_.markers_drawn;
    if (!frame.seen[ii]) continue;
    ++report_.markers_labelled;
    // The spot drawn nearest to the reported position says which marker it really is.
    int nearest = -1;
    double best = INFINITY;
    for (int k = 0; k < kMarkers; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      if (!truth.visible[kk]) continue;
      const double d = (frame.uv[ii] - truth.uv[kk]).norm();
      if (d < best) {
        best = d;
        nearest = k;
      }
    }
    if (nearest != i) {
      ++report_.wrong_labels;
      continue;
    }
    sum_sq_ += best * best;
    report_.centroid_max_px = std::max(report_.centroid_max_px, best);
  }
}

DetectionReport RenderedMarkers::report() const {
  DetectionReport r = report_;
  const std::uint64_t good = r.markers_labelled - r.wrong_labels;
  r.centroid_rms_px = good > 0 ? std::sqrt(sum_sq_ / static_cast<double>(good)) : 0.0;
  r.ms_per_frame =
      r.frames > 0 ? 1e3 * detect_.counters().detect_seconds / static_cast<double>(r.frames) : 0.0;
  const drivers::IdentifierCounters& id = detect_.identifier_counters();
  r.dropped_in_doubt = id.ambiguous + id.crossing + id.refused;
  r.unlabelled_blobs = id.unassigned;
  return r;
}

}  // namespace mirrorcal::app
