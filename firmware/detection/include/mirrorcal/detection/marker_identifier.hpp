// Which marker is which blob. Four cues: where the filter predicts each marker's reflection (a
// Mahalanobis gate on the predicted covariance), how bright each marker is relative to the others
// (the rig's markers differ in brightness, 1 : 1.5 : 2.25 by default, so the ratio of two blobs'
// fluxes names them even while the prediction is still vague), where the markers' places on the
// rig are known to about a centimetre, whether one plane mirror shows the labelled blobs
// (mirror_fit.hpp), and for identical LEDs under loose priors, the name of each blob's track, from
// the rig's shape fitted over frames (shape_bootstrap.hpp). Every assignment of blobs
// to markers within the gates is scored; the best wins, and a marker that some other assignment
// within a margin of the best labels differently is dropped, as are markers whose predictions lie
// on top of each other (crossing), and blobs too spread out to be one spot (two merged reflections)
// or too close to another blob to be measured cleanly. A missing marker costs more than a poor
// match, a wrong label is avoided at the price of a frame. Header-only; nothing allocates.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/mirror_fit.hpp"
#include "mirrorcal/estimator/mirror_model.hpp"
#include "mirrorcal/hal/frames.hpp"

namespace mirrorcal::detection {

// How badly n spots' fluxes fit the brightness ratios of the markers they are named
// (log_brightness[k]: the log of spot k's marker's brightness), with the common scale (the
// exposure, the distance) fitted to the unclipped ones: sum of squared log residuals about their
// mean over sigma^2. A clipped spot's flux is a lower bound: it costs only where even that is
// brighter than its marker's share (the brightest LED's clipped spot named the dimmest).
inline double brightness_misfit(const double* flux, const bool* clipped,
                                const double* log_brightness, int n, double sigma) {
  double mean = 0.0;
  int unclipped = 0;
  for (int k = 0; k < n; ++k)
    if (!clipped[k]) {
      mean += std::log(flux[k]) - log_brightness[k];
      ++unclipped;
    }
  if (n < 2 || unclipped == 0) return 0.0;
  mean /= unclipped;
  double ss = 0.0;
  for (int k = 0; k < n; ++k) {
    const double r = std::log(flux[k]) - log_brightness[k] - mean;
    if (!clipped[k] || r > 0.0) ss += r * r;
  }
  return ss / (sigma * sigma);
}

template <int M>
struct IdentifierConfig {
  // Squared Mahalanobis distance (2 dof) beyond which a blob cannot be the marker: 99.9 %.
  double gate_chi2 = 13.8155;
  // Added to the predicted covariance (px, 1-sigma per axis): the centroid's noise and the motion
  // between the filter's time and the frame's (up to one IMU period).
  double extra_sigma_px = 3.0;
  // Relative brightness of the markers (any scale); all equal switches the cue off.
  std::array<double, M> brightness = default_brightness();
  double log_flux_sigma = 0.15;  // spread of log(flux) about the brightness model
  // A blob whose brightest pixel reaches this luma is clipped (an exposure set for the dimmer
  // LEDs): its flux is only a lower bound on its LED's.
  int saturated_luma = 250;
  // A runner-up assignment costing less than this much more than the best puts every label it
  // disputes in doubt.
  double ambiguity_margin = 6.0;
  // Two markers predicted closer than this (px) with a confident prediction are crossing: their
  // reflections merge or may swap, so both are dropped.
  double min_separation_px = 6.0;
  // The detector's crowding distance (px: twice its centroid radius), and the centroids' noise
  // (px, 1-sigma per axis) the calibration assumes.
  double crowded_px = 7.0;
  double pixel_sigma_px = 1.0;
  // Confident predictions closer than this are crossing too: beyond the crowding distance by 3
  // sigmas of two centroids' separation. Nearer, whether this frame's blobs were crowded, merged
  // or in doubt turned on this frame's noise, and the labels kept were a selection of it: pairs
  // measured apart kept, pairs measured together withheld, which biased the markers' separation
  // (a rig whose two reflections passed within 10 px for half the recording: NEES 147, consistent
  // by every self-check). Decided on the prediction, which this frame's noise is not in.
  double crossing_px() const {
    return std::max(min_separation_px, crowded_px + 3.0 * std::sqrt(2.0) * pixel_sigma_px);
  }
  // A blob whose spread (px^2) exceeds this is more than one spot.
  double max_spread_px2 = 4.0;
  // The rig's geometry, for the mirror's cue: each labelling of two or more markers costs its
  // plane mirror's fit (chi-square, 2 n - 3 dof). Off by default: it needs the markers known to
  // about a centimetre (mirror_fit_test: 99 % of frames told apart at 1 cm, 69 % at 2 cm).
  bool use_geometry = false;
  RigGeometry<M> geometry{};
  // The track cue (shape_bootstrap.hpp): naming a blob otherwise than its track's name, or a
  // blob of no named track a marker whose name another blob's track holds, costs this much. More
  // than the ambiguity margin, so that a track's name decides where nothing else does; less than
  // a sharp prediction's disagreement, which overrules it.
  double track_cost = 12.0;
  // A prediction this sharp (its larger sigma, px) needs no track cue: the filter has the marker,
  // and a track that swapped with a room light's as the two passed (whose names the cue would
  // then swap) is outvoted however close the two lights are.
  double sharp_sigma_px = 2.0;

  static constexpr std::array<double, M> default_brightness() {
    std::array<double, M> b{};
    double v = 1.0;
    for (int i = 0; i < M; ++i) {
      b[static_cast<std::size_t>(i)] = v;
      v *= 1.5;
    }
    return b;
  }
};

struct IdentifierCounters {
  std::uint64_t frames = 0;
  std::uint64_t identified = 0;  // markers labelled
  std::uint64_t ambiguous = 0;   // markers dropped because the label was in doubt
  std::uint64_t crossing = 0;    // markers dropped because their predictions met
  std::uint64_t refused = 0;     // blobs refused: two spots in one, crowded, or cut by the edge
  std::uint64_t unassigned = 0;  // blobs left over (spurious, or markers out of the gates)

  IdentifierCounters& operator+=(const IdentifierCounters& o) {
    frames += o.frames;
    identified += o.identified;
    ambiguous += o.ambiguous;
    crossing += o.crossing;
    refused += o.refused;
    unassigned += o.unassigned;
    return *this;
  }
};

template <int M>
class MarkerIdentifier {
 public:
  static constexpr int kMaxBlobs = 32;
  // The blobs considered per marker: the nearest to its prediction, or without one the brightest.
  static constexpr int kCandidates = 6;

  explicit MarkerIdentifier(const IdentifierConfig<M>& config) : config_(config) {
    for (int i = 0; i < M; ++i)
      log_brightness_[i] = std::log(config.brightness[static_cast<std::size_t>(i)]);
  }

  // Labels blobs[0..n) into frame (seen/uv; t_ns is the caller's) and says what it met.
  // prediction may be null: then brightness alone decides. track_labels, if given, names each
  // blob by its track (a marker, or -1). dark_marker: a marker whose LED the blink code darkened
  // in this frame (hal/blink_code.hpp), which no blob is labelled as; -1: none.
  IdentifierCounters identify(const Blob* blobs, int n, const hal::MarkerPrediction<M>* prediction,
                              MarkerFrame<M>& frame, const int* track_labels = nullptr,
                              int dark_marker = -1) {
    IdentifierCounters counters;
    counters.frames = 1;
    frame.seen.fill(false);
    labelled_.fill(-1);
    if (n > kMaxBlobs) n = kMaxBlobs;
    blobs_ = blobs;

    // Candidate blobs per marker, nearest first by Mahalanobis distance.
    std::array<bool, M> crossing{};
    const std::array<bool, M> held = names_held(blobs, n, track_labels);
    for (int i = 0; i < M; ++i) {
      count_[i] = 0;
      if (i == dark_marker) continue;
      const bool predicted =
          prediction == nullptr || prediction->valid[static_cast<std::size_t>(i)];
      if (!predicted) {
        // No prediction of this marker (its sigma points leave the image: the filter has had no
        // marker for a while): its track's blob, if a track is named after it.
        for (int j = 0; j < n && track_labels != nullptr; ++j)
          if (track_labels[j] == i && single_spot(blobs[j])) insert_candidate(i, j, 0.0, 0.0);
        continue;
      }
      Eigen::Matrix2d info = Eigen::Matrix2d::Identity();
      if (prediction != nullptr) {
        const Eigen::Matrix2d c =
            prediction->covariance[static_cast<std::size_t>(i)] +
            config_.extra_sigma_px * config_.extra_sigma_px * Eigen::Matrix2d::Identity();
        info = c.inverse();
      }
      const bool track_cue = track_labels != nullptr && !sharp(prediction, i);
      for (int j = 0; j < n; ++j) {
        if (!single_spot(blobs[j])) continue;
        const double against_track =
            track_cue && otherwise_named(track_labels[j], i, held) ? config_.track_cost : 0.0;
        if (prediction == nullptr) {
          // Without a prediction every blob is as near as any other: the brightest are the
          // candidates (markers are the scene's bright spots), whatever their order in the image.
          // and a blob whose track is named i first of all.
          const bool tracked_as_i = track_labels != nullptr && track_labels[j] == i;
          insert_candidate(i, j, against_track, (tracked_as_i ? -1e30 : 0.0) - blobs[j].flux);
          continue;
        }
        const Eigen::Vector2d r =
            Eigen::Vector2d(blobs[j].u, blobs[j].v) - prediction->uv[static_cast<std::size_t>(i)];
        const double d2 = r.dot(info * r);
        if (!(d2 <= config_.gate_chi2)) continue;
        insert_candidate(i, j, d2 + against_track, d2 + against_track);
      }
    }
    for (int j = 0; j < n; ++j)
      if (!single_spot(blobs[j])) ++counters.refused;
    if (prediction != nullptr) mark_crossing(*prediction, crossing);

    // The best assignment; then, per marker, the cheapest assignment that labels it otherwise.
    best_cost_ = std::numeric_limits<double>::infinity();
    used_.fill(false);
    search(0, 0.0, false);
    alt_cost_.fill(std::numeric_limits<double>::infinity());
    search(0, 0.0, true);

    int labelled = 0;
    for (int i = 0; i < M; ++i) {
      const int j = best_[i];
      if (j < 0) continue;
      if (crossing[static_cast<std::size_t>(i)]) {
        ++counters.crossing;
        continue;
      }
      if (alt_cost_[static_cast<std::size_t>(i)] < best_cost_ + config_.ambiguity_margin) {
        ++counters.ambiguous;
        continue;
      }
      frame.seen[static_cast<std::size_t>(i)] = true;
      frame.uv[static_cast<std::size_t>(i)] = Eigen::Vector2d(blobs[j].u, blobs[j].v);
      labelled_[static_cast<std::size_t>(i)] = j;
      ++labelled;
    }
    counters.identified += static_cast<std::uint64_t>(labelled);
    int assigned = 0;
    for (int i = 0; i < M; ++i) assigned += best_[i] >= 0 ? 1 : 0;
    counters.unassigned += static_cast<std::uint64_t>(n - assigned);
    return counters;
  }

  const IdentifierConfig<M>& config() const { return config_; }

  // Whether prediction (null: none) places marker i within sharp_sigma_px.
  bool sharp(const hal::MarkerPrediction<M>* prediction, int i) const {
    if (prediction == nullptr || !prediction->valid[static_cast<std::size_t>(i)]) return false;
    const Eigen::Matrix2d& c = prediction->covariance[static_cast<std::size_t>(i)];
    const double larger = 0.5 * (c.trace() + std::hypot(c(0, 0) - c(1, 1), 2.0 * c(0, 1)));
    return larger < config_.sharp_sigma_px * config_.sharp_sigma_px;
  }

  // The blob the last identify() labelled marker i with, or -1.
  int blob_of(int i) const { return labelled_[static_cast<std::size_t>(i)]; }

 private:
  bool single_spot(const Blob& b) const {
    return detection::single_spot(b, config_.max_spread_px2);
  }

  // Which markers' names a track of this frame's single spots holds.
  std::array<bool, M> names_held(const Blob* blobs, int n, const int* track_labels) const {
    std::array<bool, M> held{};
    for (int j = 0; j < n && track_labels != nullptr; ++j)
      if (track_labels[j] >= 0 && track_labels[j] < M && single_spot(blobs[j]))
        held[std::size_t(track_labels[j])] = true;
    return held;
  }

  // Whether the track cue speaks against naming a blob whose track is named `label` (-1: none)
  // marker i: its track holds another name, or it holds none while another blob's track holds
  // i's (a room light's spot is as near a vague prediction as the reflection its track follows).
  static bool otherwise_named(int label, int i, const std::array<bool, M>& held) {
    return label >= 0 ? label != i : held[std::size_t(i)];
  }

  // Keeps marker i's kCandidates blobs of lowest rank, each with its cost d2.
  void insert_candidate(int i, int j, double d2, double rank) {
    int k = count_[i] < kCandidates ? count_[i]++ : kCandidates;
    if (k == kCandidates) {
      if (rank >= cand_rank_[i][kCandidates - 1]) return;
      k = kCandidates - 1;
    }
    while (k > 0 && cand_rank_[i][k - 1] > rank) {
      cand_[i][k] = cand_[i][k - 1];
      cand_d2_[i][k] = cand_d2_[i][k - 1];
      cand_rank_[i][k] = cand_rank_[i][k - 1];
      --k;
    }
    cand_[i][k] = j;
    cand_d2_[i][k] = d2;
    cand_rank_[i][k] = rank;
  }

  // Markers whose predictions coincide while both are confident: crossing reflections.
  void mark_crossing(const hal::MarkerPrediction<M>& p, std::array<bool, M>& crossing) const {
    const double sep2 = config_.crossing_px() * config_.crossing_px();
    const double confident2 = config_.min_separation_px * config_.min_separation_px;
    for (int i = 0; i < M; ++i)
      for (int k = i + 1; k < M; ++k) {
        const auto a = static_cast<std::size_t>(i), b = static_cast<std::size_t>(k);
        if (!p.valid[a] || !p.valid[b]) continue;
        const double spread = p.covariance[a].trace() + p.covariance[b].trace();
        if ((p.uv[a] - p.uv[b]).squaredNorm() < sep2 && spread < confident2)
          crossing[a] = crossing[b] = true;
      }
  }

  // Depth-first over the assignments (costs only grow, so a partial cost prunes). The first pass
  // finds the best; the second (alternatives) records, per marker, the cheapest assignment that
  // labels it otherwise, among those within the ambiguity margin of the best.
  void search(int i, double cost, bool alternatives) {
    const double bound = alternatives ? best_cost_ + config_.ambiguity_margin : best_cost_;
    if (cost >= bound) return;
    if (i == M) {
      cost += brightness_cost() + geometry_cost();
      if (cost >= bound) return;
      if (!alternatives) {
        best_cost_ = cost;
        best_ = current_;
        return;
      }
      for (int k = 0; k < M; ++k) {
        auto& alt = alt_cost_[static_cast<std::size_t>(k)];
        if (current_[k] != best_[k] && cost < alt) alt = cost;
      }
      return;
    }
    current_[i] = -1;  // not seen: costs as much as a blob at the gate's edge
    search(i + 1, cost + config_.gate_chi2, alternatives);
    for (int k = 0; k < count_[i]; ++k) {
      const int j = cand_[i][k];
      if (used_[static_cast<std::size_t>(j)]) continue;
      used_[static_cast<std::size_t>(j)] = true;
      current_[i] = j;
      search(i + 1, cost + cand_d2_[i][k], alternatives);
      used_[static_cast<std::size_t>(j)] = false;
    }
    current_[i] = -1;
  }

  // How badly the labelled blobs' fluxes fit the brightness ratios (brightness_misfit).
  double brightness_cost() const {
    double flux[M], log_brightness[M];
    bool clipped[M];
    int n = 0;
    for (int i = 0; i < M; ++i) {
      const int j = current_[i];
      if (j < 0) continue;
      flux[n] = blobs_[j].flux;
      clipped[n] = blobs_[j].peak >= config_.saturated_luma;
      log_brightness[n++] = log_brightness_[i];
    }
    return brightness_misfit(flux, clipped, log_brightness, n, config_.log_flux_sigma);
  }

  // How badly one plane mirror shows the labelled blobs where the rig's markers are: 0 without
  // the cue or with fewer than two labelled (a single blob fits any mirror), infinite where no
  // plane in front of the camera shows them.
  double geometry_cost() const {
    if (!config_.use_geometry) return 0.0;
    std::array<bool, M> seen{};
    std::array<Eigen::Vector2d, M> uv{};
    for (int i = 0; i < M; ++i) {
      const int j = current_[i];
      if (j < 0) continue;
      seen[static_cast<std::size_t>(i)] = true;
      uv[static_cast<std::size_t>(i)] = Eigen::Vector2d(blobs_[j].u, blobs_[j].v);
    }
    return fit_mirror<M>(config_.geometry, seen, uv).cost;
  }

  IdentifierConfig<M> config_;
  double log_brightness_[M]{};
  const Blob* blobs_ = nullptr;
  int count_[M]{};
  int cand_[M][kCandidates]{};
  double cand_d2_[M][kCandidates]{};
  double cand_rank_[M][kCandidates]{};
  std::array<bool, kMaxBlobs> used_{};
  std::array<int, M> current_{}, best_{}, labelled_{};
  std::array<double, M> alt_cost_{};
  double best_cost_ = 0.0;
};

}  // namespace mirrorcal::detection
