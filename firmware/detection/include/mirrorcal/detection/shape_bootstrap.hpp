// Identical LEDs under loose priors: before the filter's prediction is sharp, no single frame
// says which reflection is which marker. The reflections are tracked from frame to frame
// (blob_tracker.hpp); every `spacing` seconds the tracks' places are taken down; and
// once kWindow such snapshots hold M tracks throughout, the rig's shape is fitted to them
// (rig_shape.hpp). A set of tracks that is not one rig's reflections (a room light drifting
// across the image, two tracks swapped where reflections crossed) does not fit, and the next
// snapshot tries again. The fit names its tracks; back from the window, the names hold as far as
// the older snapshots show the named tracks where the shape has them (another track may have
// held a name there: checked_back), and on from it, each snapshot checks them the same way (a
// named track may follow a room light off its reflection: checked_on). A track keeps its name
// while it lives: the identifier's track cue (marker_identifier.hpp) labels each frame's blobs by
// their tracks' names until the filter's prediction is sharp. A new track takes the name the
// identifier gives its blob with the prediction (confirm), if no live track holds it; a sharp
// prediction renames a track outright. Header-only; nothing allocates.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/blob_tracker.hpp"
#include "mirrorcal/detection/marker_identifier.hpp"
#include "mirrorcal/detection/rig_shape.hpp"

namespace mirrorcal::detection {

// A name a track holds over a span of frames: named checked back from the window (the track
// that held a name before the window may be another than the one that holds it there: the
// reflection was tracked by a track that had followed a light, or two tracks swapped).
struct NamedSpan {
  int track = -1;  // -1: no span
  int label = -1;
  std::int64_t from_ns = std::numeric_limits<std::int64_t>::min();
  std::int64_t until_ns = std::numeric_limits<std::int64_t>::max();
};

// Which track each name went to (track_of_label[i]: the track named i, by the order tracks are
// started in; -1 for a name not given) and the spans of frames each name is held over, back from
// the window as far as the snapshots show the named tracks as the shape (ShapeBootstrap's
// checked_back). A frame outside every span is labelled by the other cues alone.
template <int M>
struct TrackNames {
  static constexpr int kMaxSpans = 4 * M;
  std::array<int, M> track_of_label{};
  std::array<NamedSpan, kMaxSpans> spans{};
  // The rig's shape the names were given by (camera frame, by name), which the named tracks are
  // checked against as they go on; none (shaped false) for names given otherwise.
  bool shaped = false;
  std::array<Eigen::Vector3d, M> shape_c{};
  bool any() const {
    return std::any_of(track_of_label.begin(), track_of_label.end(),
                       [](int id) { return id >= 0; });
  }
  // The name track id holds at t_ns, or -1.
  int label_at(int id, std::int64_t t_ns) const {
    for (const NamedSpan& s : spans)
      if (s.track == id && s.from_ns <= t_ns && t_ns <= s.until_ns) return s.label;
    return -1;
  }
  // From then on every name is held by its track at the window.
  std::int64_t settled_ns() const {
    std::int64_t t = std::numeric_limits<std::int64_t>::min();
    for (const NamedSpan& s : spans)
      if (s.track >= 0 && s.until_ns == std::numeric_limits<std::int64_t>::max())
        t = std::max(t, s.from_ns);
    return t;
  }
};
template <int M>
TrackNames<M> no_track_names() {
  TrackNames<M> t{};
  t.track_of_label.fill(-1);
  return t;
}
// Each name held by its track from the first frame on.
template <int M>
TrackNames<M> names_throughout(const std::array<int, M>& track_of_label) {
  TrackNames<M> t = no_track_names<M>();
  t.track_of_label = track_of_label;
  for (int i = 0; i < M; ++i)
    t.spans[std::size_t(i)] = NamedSpan{track_of_label[std::size_t(i)], i};
  return t;
}

struct ShapeBootstrapCounters {
  std::uint64_t windows_tried = 0;  // windows of tracks fitted
  std::int64_t made_at_ns = -1;     // the frame whose window gave the names (-1: not yet)
  std::uint64_t renamed = 0;        // names the snapshots after it moved to another track
};

template <int M>
class ShapeBootstrap {
 public:
  static constexpr int kWindow = 16;
  // Snapshots kept: the window's, and those before it that the names are checked back through.
  static constexpr int kHistory = 48;
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
  // frames starts the same tracks, so each is named over its spans, where the look had to wait
  // for its window to fill.
  void name_ahead(const TrackNames<M>& names) {
    names_ = names;
    named_ahead_ = names.any();
    settled_ns_ = names.settled_ns();
  }
  // The names given, as name_ahead() takes them.
  const TrackNames<M>& names() const { return names_; }
  bool named() const { return shape_.made || named_ahead_; }

  // One frame's blobs (single spots only are tracked); until the shape is fitted, a window tried
  // at each snapshot. Then blob_labels() names this frame's blobs by their tracks.
  void feed(std::int64_t t_ns, const Blob* blobs, int n) {
    tracker_.track(t_ns, blobs, n,
                   [&](int id) { return named_ahead_ ? names_.label_at(id, t_ns) : -1; });
    // Until every name is settled on its track at the window, the spans say which track holds
    // which name in each frame; from then on the tracks keep them (and confirm() renames).
    if (named_ahead_ && !named_ahead_settled_) {
      for (BlobTrack& tr : tracker_.tracks())
        if (tr.id >= 0) tr.label = names_.label_at(tr.id, t_ns);
      named_ahead_settled_ = t_ns >= settled_ns_;
    }
    if (!named() && snapshot_due(t_ns)) {
      take_snapshot(t_ns);
      if (snapshots_ >= kWindow) try_window(t_ns);
    } else if (names_.shaped && settled() && snapshot_due(t_ns)) {
      take_snapshot(t_ns);
      checked_on();
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
    std::int64_t t_ns = 0;
    int n = 0;
    std::array<int, kMaxTracks> id{};
    std::array<Eigen::Vector2d, kMaxTracks> uv{};
  };

  // The tracks measured in this frame (a clean spot, not one crowded by a lamp), into the ring of
  // snapshots.
  void take_snapshot(std::int64_t t_ns) {
    Snapshot& s = ring_[std::size_t(head_)];
    s.t_ns = t_ns;
    s.n = 0;
    for (const BlobTrack& tr : tracker_.tracks())
      if (tr.id >= 0 && tr.missed == 0 && tr.measured) {
        s.id[std::size_t(s.n)] = tr.id;
        s.uv[std::size_t(s.n)] = tr.uv;
        ++s.n;
      }
    head_ = (head_ + 1) % kHistory;
    snapshots_ = std::min(snapshots_ + 1, kHistory);
    ++snapshots_taken_;
    last_snapshot_ns_ = t_ns;
  }

  // The snapshot taken `back` snapshots before the newest (0: the newest).
  const Snapshot& newest(int back) const {
    return ring_[std::size_t((head_ + kHistory - 1 - back) % kHistory)];
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
    for (int i = 0; i < newest(0).n; ++i) {
      const int id = newest(0).id[std::size_t(i)];
      bool everywhere = true;
      Eigen::Vector2d uv;
      for (int k = 0; k < kWindow; ++k) everywhere = everywhere && place(newest(k), id, uv);
      if (everywhere) common[std::size_t(nc++)] = id;
    }
    if (nc < M) return;
    std::sort(common.begin(), common.begin() + nc,
              [this](int a, int b) { return flux_of(a) > flux_of(b); });
    std::array<int, M> pick{};
    for (int j = 0; j < M; ++j) pick[std::size_t(j)] = j;
    for (int tried = 0; tried < kMaxSubsets; ++tried) {
      TrackWindow<M, kWindow> w;
      for (int k = 0; k < kWindow; ++k)  // oldest first
        for (int j = 0; j < M; ++j)
          place(newest(kWindow - 1 - k), common[std::size_t(pick[std::size_t(j)])],
                w.uv[std::size_t(k)][std::size_t(j)]);
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
          names_.track_of_label[std::size_t(shape.label_of_track[std::size_t(j)])] = id;
          for (BlobTrack& tr : tracker_.tracks())
            if (tr.id == id) tr.label = shape.label_of_track[std::size_t(j)];
        }
        names_.shaped = true;
        names_.shape_c = shape.geometry.markers_c;
        checked_back();
        return;
      }
      if (!next_combination(pick, nc)) return;
    }
  }

  // The spans the names hold over, back from the newest snapshot: in each snapshot a plane mirror
  // shows the named tracks where the shape has them, and clearly better than under any other
  // naming (two named tracks swapped, or another track in a named one's place). Where another
  // naming fits clearly better, the names go to its tracks before that snapshot: a reflection
  // tracked by a track that had followed a light, or two tracks swapped where their reflections
  // passed. One snapshot that shows no naming well (a track crowded by a lamp's tail, unseen) is
  // passed over; two in a row, a snapshot no naming clearly fits, or no span left, end the names
  // there. The window's own snapshots are checked too: its fit's bound, over all of them, passes
  // a track that was a light's in a few.
  void checked_back() {
    const RigGeometry<M> exact = exact_shape();
    std::array<int, M> names = names_.track_of_label;
    std::array<std::int64_t, M> held{}, until{};
    held.fill(newest(0).t_ns);
    until.fill(std::numeric_limits<std::int64_t>::max());
    int spans = 0, misses = 0, back = 1;
    for (; back < snapshots_; ++back) {
      const Snapshot& s = newest(back);
      std::array<int, M> seen = names;
      const NamesSeen how = names_seen(s, exact, seen);
      if (how == NamesSeen::kNoNamingWell && ++misses < 2) continue;
      if (how != NamesSeen::kClearly) break;
      misses = 0;
      int changed = 0;
      for (int i = 0; i < M; ++i) changed += seen[std::size_t(i)] != names[std::size_t(i)];
      if (spans + changed > TrackNames<M>::kMaxSpans - M) break;
      for (int i = 0; i < M; ++i) {
        const std::size_t ii = std::size_t(i);
        if (seen[ii] != names[ii]) {
          names_.spans[std::size_t(spans++)] = NamedSpan{names[ii], i, held[ii], until[ii]};
          names[ii] = seen[ii];
          until[ii] = s.t_ns;
        }
        held[ii] = s.t_ns;
      }
    }
    // Back to the first snapshot of the recording: the names hold from the first frame.
    const bool from_first = back == snapshots_ && misses == 0 && snapshots_taken_ == snapshots_;
    for (int i = 0; i < M; ++i)
      names_.spans[std::size_t(spans++)] =
          NamedSpan{names[std::size_t(i)], i,
                    from_first ? std::numeric_limits<std::int64_t>::min() : held[std::size_t(i)],
                    until[std::size_t(i)]};
  }

  // The shape that gave the names, as it is: its sigma is mostly its common offset's, which the
  // mirror hides, and charged in every frame it would let a track 10 px off pass.
  RigGeometry<M> exact_shape() const {
    RigGeometry<M> exact = prior_;
    exact.markers_c = names_.shape_c;
    exact.marker_sigma_m = 0.0;
    return exact;
  }

  // Whether each name is held by its track as the names were given: from the window's fit on, or
  // once the spans of names given ahead have run to their last track.
  bool settled() const { return shape_.made || named_ahead_settled_; }

  // The names checked on, at each snapshot once they are settled, as checked_back() checks them
  // back: where another naming clearly shows the shape, its tracks take the names (a named track
  // that followed a room light off its reflection, a name whose track ended given to the one that
  // took the reflection up). A snapshot that shows no naming clearly changes nothing.
  void checked_on() {
    const RigGeometry<M> exact = exact_shape();
    std::array<int, M> names;
    names.fill(-1);
    for (const BlobTrack& tr : tracker_.tracks())
      if (tr.id >= 0 && tr.label >= 0) names[std::size_t(tr.label)] = tr.id;
    std::array<int, M> seen = names;
    if (names_seen(newest(0), exact, seen) != NamesSeen::kClearly) return;
    for (int i = 0; i < M; ++i) {
      if (seen[std::size_t(i)] == names[std::size_t(i)]) continue;
      for (BlobTrack& tr : tracker_.tracks())
        if (tr.id >= 0 && (tr.label == i || tr.id == seen[std::size_t(i)]))
          tr.label = tr.id == seen[std::size_t(i)] ? i : -1;
      ++counters_.renamed;
    }
  }

  enum class NamesSeen { kClearly, kNoNamingWell, kAmbiguous };
  // Which naming of snapshot s's tracks shows the shape, from `names` (track ids by name, -1 for
  // a name no track holds; in: those of the next snapshot, out: this one's): they, two of them
  // swapped, or one's place taken by another track. Clearly: the best fits the mirror's chi-square
  // (its mean and six standard deviations, 2 M - 3 dof) by a margin over the next.
  NamesSeen names_seen(const Snapshot& s, const RigGeometry<M>& shape,
                       std::array<int, M>& names) const {
    constexpr int dof = 2 * M - 3;
    const double bound = dof + 6.0 * std::sqrt(2.0 * dof), margin = 9.0;
    double best = std::numeric_limits<double>::infinity(), next = best;
    std::array<int, M> best_names = names;
    const auto consider = [&](const std::array<int, M>& candidate) {
      if (candidate == best_names && best < std::numeric_limits<double>::infinity()) return;
      std::array<bool, M> all{};
      all.fill(true);
      std::array<Eigen::Vector2d, M> uv;
      for (int i = 0; i < M; ++i)
        if (!place(s, candidate[std::size_t(i)], uv[std::size_t(i)])) return;
      const double cost = fit_mirror<M>(shape, all, uv).cost;
      if (cost < best) {
        next = best;
        best = cost;
        best_names = candidate;
      } else {
        next = std::min(next, cost);
      }
    };
    // The namings near `from`: it, two of its tracks swapped, or one's place taken by another.
    const auto near = [&](const std::array<int, M>& from) {
      consider(from);
      for (int i = 0; i < M; ++i) {
        for (int j = i + 1; j < M; ++j) {
          std::array<int, M> swapped = from;
          std::swap(swapped[std::size_t(i)], swapped[std::size_t(j)]);
          consider(swapped);
        }
        for (int t = 0; t < s.n; ++t) {
          const int id = s.id[std::size_t(t)];
          if (std::find(from.begin(), from.end(), id) != from.end()) continue;
          std::array<int, M> taken = from;
          taken[std::size_t(i)] = id;
          consider(taken);
        }
      }
    };
    // A name no track holds (its track ended where two reflections merged) is given to each track
    // that holds none in turn, and the namings near each tried: the others may have swapped there.
    const auto unheld = std::find(names.begin(), names.end(), -1);
    for (int t = 0; t < s.n && unheld != names.end(); ++t) {
      const int id = s.id[std::size_t(t)];
      if (std::find(names.begin(), names.end(), id) != names.end()) continue;
      std::array<int, M> filled = names;
      filled[std::size_t(unheld - names.begin())] = id;
      near(filled);
    }
    if (unheld == names.end()) near(names);
    if (!(best < bound)) return NamesSeen::kNoNamingWell;
    if (!(best + margin < next)) return NamesSeen::kAmbiguous;
    names = best_names;
    return NamesSeen::kClearly;
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
  std::array<Snapshot, kHistory> ring_{};
  int head_ = 0, snapshots_ = 0;  // snapshots_: those held (at most kHistory)
  std::int64_t snapshots_taken_ = 0;
  std::int64_t last_snapshot_ns_ = -(std::int64_t{1} << 62);
  RigShape<M> shape_{};
  TrackNames<M> names_ = no_track_names<M>();
  bool named_ahead_ = false, named_ahead_settled_ = false;
  std::int64_t settled_ns_ = 0;
  ShapeBootstrapCounters counters_{};
  // The LEDs' brightness code (coded_: not all equal), as the identifier has it.
  std::array<double, M> log_brightness_{};
  bool coded_ = false;
  double log_flux_sigma_;
  int saturated_luma_;
  BlobTrack none_{};
};

}  // namespace mirrorcal::detection
