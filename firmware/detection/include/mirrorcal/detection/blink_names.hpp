// Identical LEDs that blink their names (hal/blink_code.hpp): the reflections are tracked from
// frame to frame (blob_tracker.hpp), and a track that went dark in marker i's dark frame, was seen
// in every other marker's dark frames and was missed off the code less often than on it, is marker
// i. A room light or a ghost never goes dark on the code, and a flickering spot goes dark off it
// too, so neither is named. A name is taken back when the code contradicts it (the track is lit in
// its marker's dark frame: it was carried onto another reflection) and when the track is missed
// while its marker is lit (it left the image, and may take up another reflection when it comes
// back); the track earns a name again from the code. The identifier's track cue
// (marker_identifier.hpp) labels each frame's blobs by their tracks' names, and no blob is labelled
// as the marker dark in its frame. Header-only; nothing allocates.
#pragma once

#include <array>
#include <cstdint>

#include "mirrorcal/detection/blob_detector.hpp"
#include "mirrorcal/detection/blob_tracker.hpp"
#include "mirrorcal/hal/blink_code.hpp"

namespace mirrorcal::detection {

struct BlinkCounters {
  std::uint64_t named = 0;     // tracks named by the code
  std::uint64_t unnamed = 0;   // named tracks seen in their marker's dark frame: names taken back
  std::uint64_t disputed = 0;  // tracks the code named as a marker a live track already is
  std::uint64_t lost = 0;      // named tracks missed while their marker was lit: names taken back
};

template <int M>
class BlinkNames {
 public:
  static constexpr int kMaxBlobs = BlobTracker::kMaxBlobs;
  // Dark frames of its marker a track must have gone dark in before it takes the name.
  static constexpr int kPeriods = 1;

  BlinkNames(const hal::BlinkCode& code, double max_spread_px2)
      : code_(code), tracker_(max_spread_px2) {
    blob_labels_.fill(-1);
  }

  // One frame's blobs, and its sequence number (the code's clock).
  void feed(std::int64_t t_ns, std::uint32_t sequence, const Blob* blobs, int n) {
    dark_ = code_.dark_marker(sequence, M);
    tracker_.track(t_ns, blobs, n, [](int) { return -1; });
    for (int t = 0; t < BlobTracker::kMaxTracks; ++t) weigh(t);
    tracker_.blob_labels(n, blob_labels_.data());
  }

  // Per blob of the last frame, its track's name (a marker), or -1.
  const int* blob_labels() const { return blob_labels_.data(); }
  // The marker dark in the last frame fed, or -1.
  int dark_marker() const { return dark_; }
  bool named(int marker) const { return tracker_.named(marker); }
  const BlinkCounters& counters() const { return counters_; }

 private:
  // What a track showed of the code since it started.
  struct Evidence {
    int id = -1;                       // the track it is of
    std::array<int, M> dark_missed{};  // marker i's dark frames the track was missed in
    std::array<int, M> dark_seen{};    // marker i's dark frames the track was seen in
    int lit_missed = 0;                // frames with every LED lit the track was missed in
  };

  // The track in slot t against this frame's code; named when the code says which marker it is.
  void weigh(int t) {
    BlobTrack& tr = tracker_.tracks()[std::size_t(t)];
    Evidence& e = evidence_[std::size_t(t)];
    if (tr.id < 0) return;
    if (e.id != tr.id) e = Evidence{tr.id, {}, {}, 0};
    // A named track missed while its marker is lit lost its reflection (the edge of the image,
    // an occlusion), and may take up another's when it comes back: the name goes.
    if (tr.label >= 0 && tr.missed > 0 && tr.label != dark_) {
      take_back(tr, e, counters_.lost);
      return;
    }
    if (dark_ < 0) {
      e.lit_missed += tr.missed > 0 ? 1 : 0;
      return;
    }
    const auto d = std::size_t(dark_);
    if (tr.missed == 0) {
      ++e.dark_seen[d];
      if (tr.label == dark_) take_back(tr, e, counters_.unnamed);  // lit where its marker is dark
      return;
    }
    ++e.dark_missed[d];
    if (tr.label >= 0 || e.dark_missed[d] < kPeriods || e.dark_seen[d] > 0) return;
    // Seen while each other marker was dark, and missed off the code less often than on it.
    int missed_elsewhere = e.lit_missed;
    for (int k = 0; k < M; ++k) {
      if (k == dark_) continue;
      if (e.dark_seen[std::size_t(k)] == 0) return;
      missed_elsewhere += e.dark_missed[std::size_t(k)];
    }
    if (missed_elsewhere >= e.dark_missed[d]) return;
    if (tracker_.named(dark_)) {
      ++counters_.disputed;
      return;
    }
    tr.label = dark_;
    ++counters_.named;
  }

  // The track's name goes, and the evidence that gave it: it starts afresh.
  static void take_back(BlobTrack& tr, Evidence& e, std::uint64_t& counter) {
    tr.label = -1;
    e = Evidence{tr.id, {}, {}, 0};
    ++counter;
  }

  hal::BlinkCode code_;
  BlobTracker tracker_;
  std::array<Evidence, BlobTracker::kMaxTracks> evidence_{};
  std::array<int, kMaxBlobs> blob_labels_{};
  int dark_ = -1;
  BlinkCounters counters_{};
};

}  // namespace mirrorcal::detection
