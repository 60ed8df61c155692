// Blobs followed from frame to frame: greedy nearest-neighbour association on each track's
// constant-velocity prediction, the closest pairs first, within a gate that widens with the
// track's speed. A track survives three frames unseen (a dark or hidden marker), then ends. Each
// track carries a name (a marker, or -1) that its owner gives it: the rig's shape fitted over
// frames (shape_bootstrap.hpp) or the LEDs' blink code (blink_names.hpp). Header-only; nothing
// allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

#include "mirrorcal/detection/blob_detector.hpp"

namespace mirrorcal::detection {

struct BlobTrack {
  int id = -1;  // -1: the slot is free; else the tracks' count when it started
  Eigen::Vector2d uv = Eigen::Vector2d::Zero(), velocity = Eigen::Vector2d::Zero();
  double flux = 0.0;
  int peak = 0;    // the last blob's brightest luma
  int missed = 0;  // frames since last seen
  std::int64_t t_ns = 0;
  int label = -1;  // the marker it is, once named
};

class BlobTracker {
 public:
  static constexpr int kMaxTracks = 12;
  static constexpr int kMaxBlobs = 32;
  static constexpr int kMaxMissed = 3;

  // max_spread_px2: the identifier's bound on one spot's spread (larger blobs are not tracked).
  explicit BlobTracker(double max_spread_px2) : max_spread_px2_(max_spread_px2) {
    blob_track_.fill(-1);
  }

  // One frame's blobs. A blob no track takes starts one, named name_new(id) (-1: unnamed).
  template <class NameNew>
  void track(std::int64_t t_ns, const Blob* blobs, int n, const NameNew& name_new) {
    n = std::min(n, kMaxBlobs);
    std::array<bool, kMaxBlobs> taken{};
    blob_track_.fill(-1);
    std::array<bool, kMaxTracks> matched{};
    for (;;) {
      double best = 0.0;
      int bt = -1, bb = -1;
      for (int t = 0; t < kMaxTracks; ++t) {
        const BlobTrack& tr = tracks_[std::size_t(t)];
        if (tr.id < 0 || matched[std::size_t(t)]) continue;
        const double dt = 1e-9 * static_cast<double>(t_ns - tr.t_ns);
        const Eigen::Vector2d predicted = tr.uv + dt * tr.velocity;
        const double gate = 15.0 + 0.5 * dt * tr.velocity.norm();
        for (int b = 0; b < n; ++b) {
          if (taken[std::size_t(b)] || !single_spot(blobs[b], max_spread_px2_)) continue;
          const double d = (Eigen::Vector2d(blobs[b].u, blobs[b].v) - predicted).norm();
          if (d < gate && (bt < 0 || d < best)) {
            best = d;
            bt = t;
            bb = b;
          }
        }
      }
      if (bt < 0) break;
      BlobTrack& tr = tracks_[std::size_t(bt)];
      const Eigen::Vector2d uv(blobs[bb].u, blobs[bb].v);
      const double dt = 1e-9 * static_cast<double>(t_ns - tr.t_ns);
      if (dt > 0.0) tr.velocity = (uv - tr.uv) / dt;
      tr.uv = uv;
      tr.flux = blobs[bb].flux;
      tr.peak = blobs[bb].peak;
      tr.missed = 0;
      tr.t_ns = t_ns;
      matched[std::size_t(bt)] = taken[std::size_t(bb)] = true;
      blob_track_[std::size_t(bb)] = bt;
    }
    for (int t = 0; t < kMaxTracks; ++t) {
      BlobTrack& tr = tracks_[std::size_t(t)];
      if (tr.id >= 0 && !matched[std::size_t(t)] && ++tr.missed > kMaxMissed) tr.id = -1;
    }
    for (int b = 0; b < n; ++b) {
      if (taken[std::size_t(b)] || !single_spot(blobs[b], max_spread_px2_)) continue;
      for (int t = 0; t < kMaxTracks; ++t)
        if (tracks_[std::size_t(t)].id < 0) {
          tracks_[std::size_t(t)] = BlobTrack{next_id_,
                                              Eigen::Vector2d(blobs[b].u, blobs[b].v),
                                              Eigen::Vector2d::Zero(),
                                              blobs[b].flux,
                                              blobs[b].peak,
                                              0,
                                              t_ns,
                                              name_new(next_id_)};
          ++next_id_;
          blob_track_[std::size_t(b)] = t;
          break;
        }
    }
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
  double max_spread_px2_;
  std::array<BlobTrack, kMaxTracks> tracks_{};
  std::array<int, kMaxBlobs> blob_track_{};  // per blob of the last frame, its track's slot
  int next_id_ = 0;
};

}  // namespace mirrorcal::detection
