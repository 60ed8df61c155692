#include "mirrorcal/evaluation/rendered_markers.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>

namespace mirrorcal::evaluation {

using namespace calibration;

namespace {

// A labelled blob further than this from every spot drawn is something else (a room light, a
// ghost) that merely lies nearest to one marker's: its label is wrong whichever. A right label's
// centroid is within a tenth of a pixel of its spot (docs/campaign/README.md, frames).
constexpr double kSameSpotPx = 3.0;

}  // namespace

DetectionReport combine(const std::vector<DetectionReport>& runs) {
  DetectionReport all;
  double sum_sq = 0.0, ms = 0.0;
  for (const DetectionReport& r : runs) {
    all.frames += r.frames;
    all.markers_drawn += r.markers_drawn;
    all.markers_labelled += r.markers_labelled;
    all.wrong_labels += r.wrong_labels;
    all.wrong_labels_before += r.wrong_labels_before;
    all.dropped_in_doubt += r.dropped_in_doubt;
    all.unlabelled_blobs += r.unlabelled_blobs;
    const double good = static_cast<double>(r.markers_labelled - r.wrong_labels);
    sum_sq += r.centroid_rms_px * r.centroid_rms_px * good;
    for (int k = 0; k < 2; ++k) all.centroid_mean_px[k] += r.centroid_mean_px[k] * good;
    all.centroid_max_px = std::max(all.centroid_max_px, r.centroid_max_px);
    ms += r.ms_per_frame * static_cast<double>(r.frames);
  }
  const double good = static_cast<double>(all.markers_labelled - all.wrong_labels);
  all.centroid_rms_px = good > 0 ? std::sqrt(sum_sq / good) : 0.0;
  for (int k = 0; k < 2; ++k)
    all.centroid_mean_px[k] = good > 0 ? all.centroid_mean_px[k] / good : 0.0;
  all.ms_per_frame = all.frames > 0 ? ms / static_cast<double>(all.frames) : 0.0;
  return all;
}

void print_detection(const DetectionReport& d, hal::PixelFormat format) {
  std::printf(
      "detection (%s frames, last pass): %llu frames, %llu of %llu reflections labelled, %llu "
      "wrong labels (%llu in earlier passes), "
      "%llu withheld in doubt, %llu blobs unlabelled; centroid error %.3f px RMS (max %.3f, "
      "mean %+.4f, %+.4f) against the spots drawn; %.2f ms per frame\n",
      hal::to_string(format), (unsigned long long)d.frames, (unsigned long long)d.markers_labelled,
      (unsigned long long)d.markers_drawn, (unsigned long long)d.wrong_labels,
      (unsigned long long)d.wrong_labels_before, (unsigned long long)d.dropped_in_doubt,
      (unsigned long long)d.unlabelled_blobs, d.centroid_rms_px, d.centroid_max_px,
      d.centroid_mean_px[0], d.centroid_mean_px[1], d.ms_per_frame);
}

template <int M>
detection::DetectionConfig<M> detection_config(const sim::RenderConfig& render,
                                               const detection::RigGeometry<M>& prior) {
  detection::DetectionConfig<M> c;
  for (int i = 0; i < M; ++i)
    c.identify.brightness[static_cast<std::size_t>(i)] =
        render.brightness[static_cast<std::size_t>(i) % render.brightness.size()];
  c.bootstrap_shape = true;
  c.prior = prior;
  c.blink = render.blink;
  return c;
}

template <int M>
RenderedMarkers<M>::RenderedMarkers(const sim::Scenario& s, const sim::RenderConfig& render,
                                    const detection::RigGeometry<M>& prior, std::uint64_t seed,
                                    const TrackNames<M>& names_ahead,
                                    const std::array<int, M>* naming)
    : frames_(s, render, seed),
      detect_(
          frames_,
          [&] {
            detection::DetectionConfig<M> c = detection_config<M>(render, prior);
            c.names_ahead = names_ahead;
            return c;
          }(),
          s.truth.width, s.truth.height) {
  std::iota(naming_.begin(), naming_.end(), 0);
  if (naming != nullptr) {
    naming_ = *naming;
    named_ = true;
  }
}

template <int M>
hal::SourceStatus RenderedMarkers<M>::poll(MarkerFrame<M>& frame) {
  const hal::SourceStatus st = detect_.poll(frame);
  if (st == hal::SourceStatus::kOk && !named_ && detect_.bootstrap().named()) record_naming();
  return st;
}

// In the frame whose window gave the names: each named blob is the LED drawn nearest to it.
template <int M>
void RenderedMarkers<M>::record_naming() {
  int n = 0;
  const detection::Blob* blobs = detect_.last_blobs(n);
  const int* labels = detect_.bootstrap().blob_labels();
  const sim::RenderedTruth& truth = frames_.truth();
  for (int b = 0; b < n; ++b) {
    if (labels[b] < 0) continue;
    double best = INFINITY;
    for (int k = 0; k < M; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      const double d = (Eigen::Vector2d(blobs[b].u, blobs[b].v) - truth.uv[kk]).norm();
      if (truth.visible[kk] && d < best) {
        best = d;
        naming_[static_cast<std::size_t>(labels[b])] = k;
      }
    }
  }
  named_ = true;
}

template <int M>
void RenderedMarkers<M>::relabel(const hal::MarkerPrediction<M>& prediction,
                                 MarkerFrame<M>& frame) {
  detect_.relabel(prediction, frame);
  // The loop holds one frame at a time, so the renderer's last frame is this one.
  const sim::RenderedTruth& truth = frames_.truth();
  ++report_.frames;
  for (int i = 0; i < M; ++i) {
    const auto ii = static_cast<std::size_t>(i);
    if (truth.visible[ii]) ++report_.markers_drawn;
    if (!frame.seen[ii]) continue;
    ++report_.markers_labelled;
    // The spot drawn nearest to the reported position says which marker it really is.
    int nearest = -1;
    double best = INFINITY;
    for (int k = 0; k < M; ++k) {
      const auto kk = static_cast<std::size_t>(k);
      if (!truth.visible[kk]) continue;
      const double d = (frame.uv[ii] - truth.uv[kk]).norm();
      if (d < best) {
        best = d;
        nearest = k;
      }
    }
    if (nearest != naming_[ii] || best > kSameSpotPx) {
      ++report_.wrong_labels;
      continue;
    }
    sum_sq_ += best * best;
    sum_u_ += frame.uv[ii].x() - truth.uv[static_cast<std::size_t>(nearest)].x();
    sum_v_ += frame.uv[ii].y() - truth.uv[static_cast<std::size_t>(nearest)].y();
    report_.centroid_max_px = std::max(report_.centroid_max_px, best);
  }
}

template <int M>
DetectionReport RenderedMarkers<M>::report() const {
  DetectionReport r = report_;
  const std::uint64_t good = r.markers_labelled - r.wrong_labels;
  r.centroid_rms_px = good > 0 ? std::sqrt(sum_sq_ / static_cast<double>(good)) : 0.0;
  r.centroid_mean_px[0] = good > 0 ? sum_u_ / static_cast<double>(good) : 0.0;
  r.centroid_mean_px[1] = good > 0 ? sum_v_ / static_cast<double>(good) : 0.0;
  r.ms_per_frame =
      r.frames > 0 ? 1e3 * detect_.counters().detect_seconds / static_cast<double>(r.frames) : 0.0;
  const detection::IdentifierCounters& id = detect_.identifier_counters();
  r.dropped_in_doubt = id.ambiguous + id.crossing + id.refused;
  r.unlabelled_blobs = id.unassigned;
  return r;
}

#define MIRRORCAL_RENDERED_MARKERS_(M)                                                 \
  template class RenderedMarkers<M>;                                                   \
  template detection::DetectionConfig<M> detection_config<M>(const sim::RenderConfig&, \
                                                             const detection::RigGeometry<M>&);
MIRRORCAL_FOR_EACH_MARKER_COUNT(MIRRORCAL_RENDERED_MARKERS_)
#undef MIRRORCAL_RENDERED_MARKERS_

}  // namespace mirrorcal::evaluation
