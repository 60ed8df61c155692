// Identical LEDs under loose priors: before the filter's prediction is sharp, no single frame
// says which reflection is which marker. The reflections are tracked from frame to frame
// (blob_tracker.hpp); every `spacing` seconds the tracks' places are taken down; and
// once kWindow such snapshots hold M tracks throughout, the rig's shape is fitted to them
// (rig_shape.hpp). A set of tracks that is not one rig's reflections (a room light drifting
// across the image, two tracks swapped where reflections crossed) does not fit, and the next
// snapshot tries again. The fit names its tracks, and a track keeps its name while it lives: the
// identifier's track cue (marker_identifier.hpp) labels each frame's blobs by their tracks' names
// until the filter's prediction is sharp. A new track takes the name the identifier gives its
// blob with the prediction (confirm), if no live track holds it; a sharp prediction renames a
// track outright. Header-only; nothing allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/blob_tracker.hpp"
#include "mirrorcal/detection/marker_identifier.hpp"
#include "mirrorcal/detection/rig_shape.hpp"

namespace mirrorcal::detection {

// Which track each name went to (track_of_label[i]: the track named i, by the order tracks are
// started in), -1 for a name not given.
template <int M>
using TrackNames = std::array<int, M>;
template <int M>
TrackNames<M> no_track_names() {
  TrackNames<M> t{};
  t.fill(-1);
  return t;
}

struct ShapeBootstrapCounters {
  std::uint64_t windows_tried = 0;  // windows of tracks fitted
  std::int64_t made_at_ns = -1;     // the frame whose window gave the names (-1: not yet)
};

template <int M>
class ShapeBootstrap {
 public:
  static constexpr int kWindow = 16;
  static constexpr int kMaxTracks = BlobTracker::kMaxTracks;
  static constexpr int kMaxBlobs = BlobTracker::kMaxBlobs;
  // Combinations of M among the snapshots' common tracks tried per window, brightest first.
  static constexpr int kMaxSubsets = 20;

  // prior: the guesses (their names and scale), the camera and pixel noise. identify: the
  // identifier's bound on one spot's spread and the LEDs' brightness code, which names count
  // against where the LEDs differ (equal: identical LEDs, the shape alone names them).
  // spacing_s: the time between snapshots (the rig must turn between them for the shape to be
  // seen).
  ShapeBootstrap(const RigGeometry<M>& prior, const IdentifierConfig<M>& identify,
                 double spacing_s = 0.5)
      : prior_(prior),
        tracker_(identify.max_spread_px2),
        spacing_ns_(static_cast<std::int64_t>(spacing_s * 1e9)),
        log_flux_sigma_(identify.log_flux_sigma),
        saturated_luma_(identify.saturated_luma) {
    blob_labels_.fill(-1);
    for (int i = 0; i < M; ++i) {
      log_brightness_[std::size_t(i)] = std::log(identify.brightness[std::size_t(i)]);
      coded_ = coded_ || identify.brightness[std::size_t(i)] != identify.brightness[0];
    }
  }

  // The names an earlier look at the same frames gave (none: no_track_names()). Tracking the same
  // frames starts the same tracks, so each is named from its first frame, where the look had to
  // wait for its window to fill.
  void name_ahead(const TrackNames<M>& track_of_label) {
    track_of_label_ = track_of_label;
    named_ahead_ =
        std::any_of(track_of_label.begin(), track_of_label.end(), [](int id) { return id >= 0; });
  }
  // The names given, as name_ahead() takes them.
  const TrackNames<M>& track_of_label() const { return track_of_label_; }
  bool named() const { return shape_.made || named_ahead_; }

  // One frame's blobs (single spots only are tracked); until the shape is fitted, a window tried
  // at each snapshot. Then blob_labels() names this frame's blobs by their tracks.
  void feed(std::int64_t t_ns, const Blob* blobs, int n) {
    tracker_.track(t_ns, blobs, n, [this](int id) { return named_ahead_ ? label_ahead(id) : -1; });
    if (!named() && snapshot_due(t_ns)) {
      take_snapshot(t_ns);
      if (snapshots_ >= kWindow) try_window(t_ns);
    }
    tracker_.blob_labels(n, blob_labels_.data());
  }

  // The identifier's labels of the last frame fed (blob_of_marker[i]: marker i's blob, or -1):
  // an unnamed track takes its blob's label if no live track holds that name. Where the
  // prediction was sharp (sharp[i]), the blob's track takes the name whatever it had, and a track
  // that held it loses it: the two had swapped as their lights passed.
  void confirm(const std::array<int, M>& blob_of_marker, const std::array<bool, M>& sharp) {
    if (!named()) return;
    for (int i = 0; i < M; ++i) {
      const int b = blob_of_marker[std::size_t(i)];
      if (b < 0 || b >= kMaxBlobs) continue;
      const int t = tracker_.track_of_blob(b);
      if (t < 0) continue;
      BlobTrack& track = tracker_.tracks()[std::size_t(t)];
      if (track.label == i) continue;
      if (sharp[std::size_t(i)]) {
        for (BlobTrack& other : tracker_.tracks())
          if (other.label == i) other.label = -1;
        track.label = i;
      } else if (track.label < 0 && !tracker_.named(i)) {
        track.label = i;
      }
    }
  }

  // Per blob of the last frame, its track's name (a marker), or -1.
  const int* blob_labels() const { return blob_labels_.data(); }
  const RigShape<M>& shape() const { return shape_; }
  const ShapeBootstrapCounters& counters() const { return counters_; }

 private:
  struct Snapshot {
    int n = 0;
    std::array<int, kMaxTracks> id{};
    std::array<Eigen::Vector2d, kMaxTracks> uv{};
  };

  // The tracks measured in this frame (a clean spot, not one crowded by a lamp), into the ring of
  // snapshots.
  void take_snapshot(std::int64_t t_ns) {
    Snapshot& s = ring_[std::size_t(head_)];
    s.n = 0;
    for (const BlobTrack& tr : tracker_.tracks())
      if (tr.id >= 0 && tr.missed == 0 && tr.measured) {
        s.id[std::size_t(s.n)] = tr.id;
        s.uv[std::size_t(s.n)] = tr.uv;
        ++s.n;
      }
    head_ = (head_ + 1) % kWindow;
    snapshots_ = std::min(snapshots_ + 1, kWindow);
    last_snapshot_ns_ = t_ns;
  }

  // A snapshot is due every spacing, but waits, up to half a spacing, while a track measured since
  // the last snapshot is not in this frame (crowded by a lamp's tail, merged with a neighbour):
  // taken then, it would leave that track out of every window it is in.
  bool snapshot_due(std::int64_t t_ns) const {
    const std::int64_t since = t_ns - last_snapshot_ns_;
    if (since < spacing_ns_) return false;
    if (since >= spacing_ns_ + spacing_ns_ / 2) return true;
    for (const BlobTrack& tr : tracker_.tracks())
      if (tr.id >= 0 && tr.measured_ns >= last_snapshot_ns_ && (tr.missed > 0 || !tr.measured))
        return false;
    return true;
  }

  // The places of track id in snapshot s, if it was seen there.
  static bool place(const Snapshot& s, int id, Eigen::Vector2d& uv) {
    for (int i = 0; i < s.n; ++i)
      if (s.id[std::size_t(i)] == id) {
        uv = s.uv[std::size_t(i)];
        return true;
      }
    return false;
  }

  // The tracks seen in every snapshot of the window, brightest first; each combination of M of
  // them fitted as the rig until one fits.
  void try_window(std::int64_t t_ns) {
    std::array<int, kMaxTracks> common{};
    int nc = 0;
    const Snapshot& newest = ring_[std::size_t((head_ + kWindow - 1) % kWindow)];
    for (int i = 0; i < newest.n; ++i) {
      const int id = newest.id[std::size_t(i)];
      bool everywhere = true;
      Eigen::Vector2d uv;
      for (const Snapshot& s : ring_) everywhere = everywhere && place(s, id, uv);
      if (everywhere) common[std::size_t(nc++)] = id;
    }
    if (nc < M) return;
    std::sort(common.begin(), common.begin() + nc,
              [this](int a, int b) { return flux_of(a) > flux_of(b); });
    std::array<int, M> pick{};
    for (int j = 0; j < M; ++j) pick[std::size_t(j)] = j;
    for (int tried = 0; tried < kMaxSubsets; ++tried) {
      TrackWindow<M, kWindow> w;
      for (int k = 0; k < kWindow; ++k)
        for (int j = 0; j < M; ++j)
          place(ring_[std::size_t((head_ + k) % kWindow)],
                common[std::size_t(pick[std::size_t(j)])], w.uv[std::size_t(k)][std::size_t(j)]);
      ++counters_.windows_tried;
      // The brightness code's cost of naming the picked tracks (names[j]: track j's marker).
      const auto brightness = [&](const std::array<int, M>& names) {
        if (!coded_) return 0.0;
        double flux[M], log_brightness[M];
        bool clipped[M];
        for (int j = 0; j < M; ++j) {
          const BlobTrack& tr = track(common[std::size_t(pick[std::size_t(j)])]);
          flux[j] = tr.flux;
          clipped[j] = tr.peak >= saturated_luma_;
          log_brightness[j] = log_brightness_[std::size_t(names[std::size_t(j)])];
        }
        return brightness_misfit(flux, clipped, log_brightness, M, log_flux_sigma_);
      };
      const RigShape<M> shape = fit_rig_shape<M, kWindow>(prior_, w, brightness);
      if (shape.made) {
        shape_ = shape;
        counters_.made_at_ns = t_ns;
        for (int j = 0; j < M; ++j) {
          const int id = common[std::size_t(pick[std::size_t(j)])];
          track_of_label_[std::size_t(shape.label_of_track[std::size_t(j)])] = id;
          for (BlobTrack& tr : tracker_.tracks())
            if (tr.id == id) tr.label = shape.label_of_track[std::size_t(j)];
        }
        return;
      }
      if (!next_combination(pick, nc)) return;
    }
  }

  int label_ahead(int id) const {
    for (int i = 0; i < M; ++i)
      if (track_of_label_[std::size_t(i)] == id) return i;
    return -1;
  }

  double flux_of(int id) const { return track(id).flux; }
  // The live track of that id (one of a window's common tracks, seen in its newest snapshot).
  const BlobTrack& track(int id) const {
    for (const BlobTrack& tr : tracker_.tracks())
      if (tr.id == id) return tr;
    return none_;
  }

  // The next combination of M indices out of n, in lexicographic order.
  static bool next_combination(std::array<int, M>& pick, int n) {
    for (int j = M - 1; j >= 0; --j)
      if (pick[std::size_t(j)] < n - M + j) {
        ++pick[std::size_t(j)];
        for (int k = j + 1; k < M; ++k) pick[std::size_t(k)] = pick[std::size_t(k - 1)] + 1;
        return true;
      }
    return false;
  }

  RigGeometry<M> prior_;
  BlobTracker tracker_;
  std::int64_t spacing_ns_;
  std::array<int, kMaxBlobs> blob_labels_{};  // per blob of the last frame, its track's name
  std::array<Snapshot, kWindow> ring_{};
  int head_ = 0, snapshots_ = 0;
  std::int64_t last_snapshot_ns_ = -(std::int64_t{1} << 62);
  RigShape<M> shape_{};
  TrackNames<M> track_of_label_ = no_track_names<M>();
  bool named_ahead_ = false;
  ShapeBootstrapCounters counters_{};
  // The LEDs' brightness code (coded_: not all equal), as the identifier has it.
  std::array<double, M> log_brightness_{};
  bool coded_ = false;
  double log_flux_sigma_;
  int saturated_luma_;
  BlobTrack none_{};
};

}  // namespace mirrorcal::detection
