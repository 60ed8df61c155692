// Blobs followed from frame to frame: nearest-neighbour association on each track's
// constant-velocity prediction (the closest pairs first, then any two pairs exchanged where that
// fits better), within a gate that widens with the track's speed. The predictions are first moved
// together by the one shift that brings most of them onto blobs: where the rig turns back, every
// reflection misses its prediction by the same 10-30 px, more than two reflections' distance. Only
// a single spot starts a track, but one that is not (crowded by a lamp's tail, cut by the image's
// edge, merged with a neighbour) carries it on unmeasured. A track unseen (a dark, hidden or lost
// reflection) coasts with the others: the rig's reflections, and the room's lights, move together
// as the rig turns, so the tracks seen in both frames move it by their mean step, and it is taken
// up again near there, after those tracks have taken their blobs. It coasts up to kMaxCoastNs while
// other tracks carry it, three frames alone, then ends. A reflection passing a lamp thus keeps its
// track, and its name, where it would otherwise start a new one, unnamed. Each track carries a name
// (a marker, or -1) that its owner gives it: the rig's shape fitted over frames
// (shape_bootstrap.hpp) or the LEDs' blink code (blink_names.hpp). Header-only; nothing allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>

#include "mirrorcal/detection/blob_detector.hpp"

namespace mirrorcal::detection {

struct BlobTrack {
  int id = -1;  // -1: the slot is free; else the tracks' count when it started
  Eigen::Vector2d uv = Eigen::Vector2d::Zero(), velocity = Eigen::Vector2d::Zero();
  double flux = 0.0;
  int peak = 0;    // the last blob's brightest luma
  int missed = 0;  // frames since last seen
  // The last blob was a single spot (single_spot()): its place is a measurement, not just a way
  // to keep the track.
  bool measured = false;
  std::int64_t t_ns = 0;          // when last seen
  std::int64_t measured_ns = -1;  // when last measured
  int label = -1;                 // the marker it is, once named
  // Where it would be now, while unseen: its last place moved by the other tracks' steps since.
  Eigen::Vector2d coasted = Eigen::Vector2d::Zero();
};

class BlobTracker {
 public:
  static constexpr int kMaxTracks = 12;
  static constexpr int kMaxBlobs = 32;
  static constexpr int kMaxMissed = 3;  // frames a track coasts alone
  // How long a track coasts on the others' steps, and how fast its gate then widens: the
  // reflections' offsets from one another drift by some 30 px/s as the rig turns briskly.
  static constexpr std::int64_t kMaxCoastNs = 500'000'000;
  static constexpr double kCoastGatePxPerS = 60.0;

  // max_spread_px2: the identifier's bound on one spot's spread (larger blobs are not tracked).
  explicit BlobTracker(double max_spread_px2) : max_spread_px2_(max_spread_px2) {
    blob_track_.fill(-1);
  }

  // One frame's blobs. A blob no track takes starts one, named name_new(id) (-1: unnamed).
  template <class NameNew>
  void track(std::int64_t t_ns, const Blob* blobs, int n, const NameNew& name_new) {
    n = std::min(n, kMaxBlobs);
    taken_.fill(false);
    blob_track_.fill(-1);
    matched_.fill(false);
    shift_ = common_shift(t_ns, blobs, n);
    // The tracks seen in the last frame first; their mean step carries the others.
    Eigen::Vector2d step_sum = Eigen::Vector2d::Zero();
    int steps = 0;
    associate(t_ns, blobs, n, true, Eigen::Vector2d::Zero(), step_sum, steps);
    const Eigen::Vector2d step =
        steps > 0 ? Eigen::Vector2d(step_sum / steps) : Eigen::Vector2d::Zero();
    const double frame_s = 1e-9 * static_cast<double>(t_ns - last_t_ns_);
    const Eigen::Vector2d common_velocity =
        steps > 0 && frame_s > 0.0 ? Eigen::Vector2d(step / frame_s) : Eigen::Vector2d::Zero();
    for (int t = 0; t < kMaxTracks; ++t) {
      BlobTrack& tr = tracks_[std::size_t(t)];
      if (tr.id < 0 || matched_[std::size_t(t)]) continue;
      const Eigen::Vector2d from = tr.missed == 0 ? tr.uv : tr.coasted;
      tr.coasted = from + (steps > 0 ? step : Eigen::Vector2d(frame_s * tr.velocity));
    }
    associate(t_ns, blobs, n, false, common_velocity, step_sum, steps);
    for (int t = 0; t < kMaxTracks; ++t) {
      BlobTrack& tr = tracks_[std::size_t(t)];
      if (tr.id < 0 || matched_[std::size_t(t)]) continue;
      ++tr.missed;
      const bool carried = steps > 0 && t_ns - tr.t_ns <= kMaxCoastNs;
      if (tr.missed > kMaxMissed && !carried) tr.id = -1;
    }
    // A new track moves as the others do, until its own steps say otherwise.
    for (int b = 0; b < n; ++b) {
      if (taken_[std::size_t(b)] || !single_spot(blobs[b], max_spread_px2_)) continue;
      const int t = free_slot();
      if (t < 0) break;
      BlobTrack& tr = tracks_[std::size_t(t)];
      tr = BlobTrack{};
      tr.id = next_id_++;
      tr.uv = Eigen::Vector2d(blobs[b].u, blobs[b].v);
      tr.velocity = common_velocity;
      tr.flux = blobs[b].flux;
      tr.peak = blobs[b].peak;
      tr.measured = true;
      tr.t_ns = tr.measured_ns = t_ns;
      tr.label = name_new(tr.id);
      blob_track_[std::size_t(b)] = t;
    }
    last_t_ns_ = t_ns;
  }

  // The slots of the tracks (BlobTrack::id < 0: free).
  std::array<BlobTrack, kMaxTracks>& tracks() { return tracks_; }
  const std::array<BlobTrack, kMaxTracks>& tracks() const { return tracks_; }
  // The slot of blob b of the last frame's track, or -1 (not tracked).
  int track_of_blob(int b) const { return blob_track_[std::size_t(b)]; }
  // Whether a live track is named label.
  bool named(int label) const {
    return std::any_of(tracks_.begin(), tracks_.end(),
                       [label](const BlobTrack& tr) { return tr.id >= 0 && tr.label == label; });
  }
  // The name of blob b of the last frame (n blobs) by its track, or -1, into labels[0..kMaxBlobs).
  void blob_labels(int n, int* labels) const {
    for (int b = 0; b < kMaxBlobs; ++b) {
      const int t = blob_track_[std::size_t(b)];
      labels[b] = b < n && t >= 0 ? tracks_[std::size_t(t)].label : -1;
    }
  }

 private:
  // A slot for a new track: a free one, else that of the track unseen longest (an unnamed one
  // first), -1 if every track was seen in this frame.
  int free_slot() const {
    int oldest = -1;
    for (int t = 0; t < kMaxTracks; ++t) {
      const BlobTrack& tr = tracks_[std::size_t(t)];
      if (tr.id < 0) return t;
      if (tr.missed == 0) continue;
      const auto rank = [](const BlobTrack& x) { return std::make_pair(x.label >= 0, x.t_ns); };
      if (oldest < 0 || rank(tr) < rank(tracks_[std::size_t(oldest)])) oldest = t;
    }
    return oldest;
  }

  // Association of the tracks seen in the last frame (seen) or of the others (at their coasted
  // places; taken up, they move on at common_velocity): greedy, the closest pair first, then any
  // two pairs exchanged where that lowers their summed squared distance. Two reflections passing
  // close by share their prediction's error (the rig turning faster or slower), which the greedy
  // choice can mistake for a swap and the sum cannot. A seen track's step is summed into step_sum.
  void associate(std::int64_t t_ns, const Blob* blobs, int n, bool seen,
                 const Eigen::Vector2d& common_velocity, Eigen::Vector2d& step_sum, int& steps) {
    std::array<Eigen::Vector2d, kMaxTracks> predicted;
    std::array<double, kMaxTracks> gate{};
    std::array<int, kMaxTracks> blob_of;
    blob_of.fill(-1);
    for (int t = 0; t < kMaxTracks; ++t) {
      const BlobTrack& tr = tracks_[std::size_t(t)];
      const double dt = 1e-9 * static_cast<double>(t_ns - tr.t_ns);
      predicted[std::size_t(t)] = seen ? prediction(tr, dt) + shift_ : tr.coasted;
      gate[std::size_t(t)] =
          seen ? 15.0 + 0.5 * dt * tr.velocity.norm() : 15.0 + kCoastGatePxPerS * dt;
    }
    const auto candidate = [&](int t) {
      const BlobTrack& tr = tracks_[std::size_t(t)];
      return tr.id >= 0 && !matched_[std::size_t(t)] && !(seen && tr.missed > 0);
    };
    const auto distance = [&](int t, int b) {
      return (Eigen::Vector2d(blobs[b].u, blobs[b].v) - predicted[std::size_t(t)]).norm();
    };
    for (;;) {
      double best = 0.0;
      int bt = -1, bb = -1;
      for (int t = 0; t < kMaxTracks; ++t) {
        if (!candidate(t)) continue;
        for (int b = 0; b < n; ++b) {
          if (taken_[std::size_t(b)] || blobs[b].wide) continue;
          const double d = distance(t, b);
          if (d < gate[std::size_t(t)] && (bt < 0 || d < best)) {
            best = d;
            bt = t;
            bb = b;
          }
        }
      }
      if (bt < 0) break;
      blob_of[std::size_t(bt)] = bb;
      matched_[std::size_t(bt)] = taken_[std::size_t(bb)] = true;
    }
    exchange_pairs(blob_of, gate, distance);
    for (int t = 0; t < kMaxTracks; ++t) {
      const int b = blob_of[std::size_t(t)];
      if (b < 0) continue;
      take_up(t, blobs[b], t_ns, seen, common_velocity, step_sum, steps);
      blob_track_[std::size_t(b)] = t;
    }
  }

  // Where a track seen in the last frame would be now at its constant velocity, dt_s after it.
  static Eigen::Vector2d prediction(const BlobTrack& tr, double dt_s) {
    return tr.uv + dt_s * tr.velocity;
  }

  // What every seen track's prediction misses by: the rig's change of pace, which moves its
  // reflections (and the room's lights) alike. Among the shifts that bring one prediction onto a
  // blob (within kMaxShiftPx), the one that brings the most onto one within kShiftFitPx (their
  // squared misses, each at most kShiftFitPx^2, summed), the smaller on a tie; then moved to those
  // predictions' mean miss. None with fewer than two such tracks: one cannot tell its own motion
  // from the others'.
  Eigen::Vector2d common_shift(std::int64_t t_ns, const Blob* blobs, int n) const {
    constexpr double kMaxShiftPx = 60.0, kShiftFitPx = 6.0;
    std::array<Eigen::Vector2d, kMaxTracks> predicted;
    int np = 0;
    for (const BlobTrack& tr : tracks_)
      if (tr.id >= 0 && tr.missed == 0)
        predicted[std::size_t(np++)] = prediction(tr, 1e-9 * static_cast<double>(t_ns - tr.t_ns));
    if (np < 2) return Eigen::Vector2d::Zero();
    // The summed truncated squared misses under shift s, and the inliers' mean miss.
    const auto misfit = [&](const Eigen::Vector2d& s, Eigen::Vector2d* mean_miss) {
      double cost = 0.0;
      Eigen::Vector2d sum = Eigen::Vector2d::Zero();
      int inliers = 0;
      for (int p = 0; p < np; ++p) {
        double nearest = kShiftFitPx * kShiftFitPx;
        Eigen::Vector2d miss = Eigen::Vector2d::Zero();
        for (int b = 0; b < n; ++b) {
          if (blobs[b].wide) continue;
          const Eigen::Vector2d d =
              Eigen::Vector2d(blobs[b].u, blobs[b].v) - predicted[std::size_t(p)] - s;
          if (d.squaredNorm() < nearest) {
            nearest = d.squaredNorm();
            miss = d;
          }
        }
        cost += nearest;
        if (nearest < kShiftFitPx * kShiftFitPx) {
          sum += miss;
          ++inliers;
        }
      }
      if (mean_miss != nullptr && inliers > 0) *mean_miss = sum / inliers;
      return cost;
    };
    Eigen::Vector2d best = Eigen::Vector2d::Zero();
    double best_cost = misfit(best, nullptr);
    for (int p = 0; p < np; ++p)
      for (int b = 0; b < n; ++b) {
        const Eigen::Vector2d s =
            Eigen::Vector2d(blobs[b].u, blobs[b].v) - predicted[std::size_t(p)];
        if (blobs[b].wide || s.norm() > kMaxShiftPx) continue;
        const double cost = misfit(s, nullptr);
        if (cost < best_cost - 1e-9 || (cost < best_cost + 1e-9 && s.norm() < best.norm())) {
          best_cost = cost;
          best = s;
        }
      }
    Eigen::Vector2d mean_miss = Eigen::Vector2d::Zero();
    misfit(best, &mean_miss);
    return best + mean_miss;
  }

  // Any two tracks' blobs exchanged while that lowers their summed squared distance (within both
  // gates).
  template <class Distance>
  static void exchange_pairs(std::array<int, kMaxTracks>& blob_of,
                             const std::array<double, kMaxTracks>& gate, const Distance& distance) {
    for (bool exchanged = true; exchanged;) {
      exchanged = false;
      for (int a = 0; a < kMaxTracks; ++a)
        for (int c = a + 1; c < kMaxTracks; ++c) {
          const int ba = blob_of[std::size_t(a)], bc = blob_of[std::size_t(c)];
          if (ba < 0 || bc < 0) continue;
          const double now = std::pow(distance(a, ba), 2) + std::pow(distance(c, bc), 2);
          const double ac = distance(a, bc), ca = distance(c, ba);
          if (ac < gate[std::size_t(a)] && ca < gate[std::size_t(c)] &&
              ac * ac + ca * ca < now - 1e-9) {
            std::swap(blob_of[std::size_t(a)], blob_of[std::size_t(c)]);
            exchanged = true;
          }
        }
    }
  }

  // Track t takes up blob b.
  void take_up(int t, const Blob& b, std::int64_t t_ns, bool seen,
               const Eigen::Vector2d& common_velocity, Eigen::Vector2d& step_sum, int& steps) {
    BlobTrack& tr = tracks_[std::size_t(t)];
    const Eigen::Vector2d uv(b.u, b.v);
    const double dt = 1e-9 * static_cast<double>(t_ns - tr.t_ns);
    tr.measured = single_spot(b, max_spread_px2_);
    if (tr.measured) tr.measured_ns = t_ns;
    if (seen) {
      step_sum += uv - tr.uv;
      ++steps;
    }
    // A step over a gap is the others' motion too, not this track's speed.
    if (!seen)
      tr.velocity = common_velocity;
    else if (dt > 0.0 && tr.measured)
      tr.velocity = (uv - tr.uv) / dt;
    tr.uv = uv;
    tr.flux = b.flux;
    tr.peak = b.peak;
    tr.missed = 0;
    tr.t_ns = t_ns;
  }

  double max_spread_px2_;
  std::array<BlobTrack, kMaxTracks> tracks_{};
  std::array<int, kMaxBlobs> blob_track_{};  // per blob of the last frame, its track's slot
  std::array<bool, kMaxBlobs> taken_{};      // this frame's blobs taken by a track
  std::array<bool, kMaxTracks> matched_{};   // this frame's tracks that took a blob
  std::int64_t last_t_ns_ = 0;
  int next_id_ = 0;
  Eigen::Vector2d shift_ = Eigen::Vector2d::Zero();  // this frame's common_shift()
};

}  // namespace mirrorcal::detection
