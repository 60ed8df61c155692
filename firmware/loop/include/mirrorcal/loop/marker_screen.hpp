// The markers of a frame judged against each other before the filter sees them. The markers sit
// fixed on one rig, so from one frame to the next their reflections move together: the steps of
// any two differ by the pixel noise and by the little the rig's rotation about the camera's axis
// and its change of distance move one more than the other (a few pixels at the random family's
// briskest, 60 Hz or 20). A blob the detector took for a marker (a room light, a reflection) or
// a label swapped with another marker's lands anywhere, and its step disagrees with the others'.
// The filter's own gate cannot tell that early on, when its prediction spreads over the image
// (CalibrationConfig::gate_after_frames); this needs no estimate at all, and none of the
// filter's state, so a wrong blob never reaches it. Fixed size: no allocation.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>

#include "mirrorcal/estimator/mirror_model.hpp"

namespace mirrorcal::loop {

struct MarkerScreenConfig {
  bool enabled = true;
  // Two markers' steps agree when they differ by less than floor_px plus noise_sigmas times the
  // pixel noise of the difference of two steps (twice the pixel sigma).
  double floor_px = 25.0;
  double noise_sigmas = 8.0;
  // Frames further apart than this (s) are not compared: every marker is taken as it comes, as
  // at the first frame.
  double max_frame_gap_s = 0.25;
  // While the filter's gate is open, a marker's first sighting waits for a second frame to
  // confirm it (off: it is taken as it comes).
  bool confirm_while_gate_open = true;
  // A marker missing from a frame, or withheld, keeps a reference that moves with the others'
  // common step for this many frames, and is then taken as it comes.
  int max_carried_frames = 3;
};

template <int M>
class MarkerScreen {
 public:
  MarkerScreen(const MarkerScreenConfig& config, double pixel_sigma)
      : config_(config), tolerance_px_(config.floor_px + config.noise_sigmas * 2.0 * pixel_sigma) {
    reference_uv_.fill(Eigen::Vector2d::Zero());
  }

  // Withholds (seen = false) the frame's markers whose step since the frame before is not that of
  // the largest group of markers whose steps agree; returns how many. When no group of two or
  // more is the largest alone (two that disagree, with no third to tell which is wrong), every
  // marker judged. A marker without a reference (its first frame, or back after an absence) is
  // taken as it comes, unless confirm: then it is withheld until a second frame agrees (not
  // counted as screened), for a filter that would take any blob (its gate still open).
  int screen(MarkerFrame<M>& frame, bool gate_open) {
    if (!config_.enabled) return 0;
    const bool confirm = gate_open && config_.confirm_while_gate_open;
    if (has_frame_ && static_cast<double>(frame.t_ns - last_t_ns_) * 1e-9 > config_.max_frame_gap_s)
      reference_.fill(false);
    has_frame_ = true;
    last_t_ns_ = frame.t_ns;
    last_withheld_ = {};
    std::array<bool, M> judged{};
    std::array<Eigen::Vector2d, M> step;
    step.fill(Eigen::Vector2d::Zero());
    int n = 0;
    for (std::size_t i = 0; i < M; ++i) {
      if (!frame.seen[i] || !reference_[i]) continue;
      step[i] = frame.uv[i] - reference_uv_[i];
      judged[i] = true;
      ++n;
    }
    // The markers kept: the largest group whose steps all agree pairwise, if it has two or more
    // and no other group is as large; else (a lone marker aside) none can be told right.
    const unsigned kept_set = n >= 2 ? agreeing_group(judged, step) : 0u;
    std::array<bool, M> withheld{};
    Eigen::Vector2d common = Eigen::Vector2d::Zero();
    int kept = 0;
    for (std::size_t i = 0; i < M; ++i) {
      withheld[i] = judged[i] && n >= 2 && (kept_set & (1u << i)) == 0;
      if (judged[i] && !withheld[i]) {
        common += step[i];
        ++kept;
      }
    }
    int count = 0;
    for (std::size_t i = 0; i < M; ++i) {
      if (frame.seen[i] && !withheld[i]) {
        if (confirm && !judged[i]) {
          frame.seen[i] = false;
          last_withheld_[i] = true;
        }
        reference_[i] = true;
        reference_uv_[i] = frame.uv[i];
        carried_[i] = 0;
        continue;
      }
      if (withheld[i]) {
        frame.seen[i] = false;
        last_withheld_[i] = true;
        ++rejected_[i];
        ++count;
      }
      // Missing or withheld: the reference moves with the markers kept (if any), for a few frames.
      // Withheld twice running, it is the reference that was wrong (a blob taken at a first
      // frame): it lapses, and the marker is taken as it comes.
      const int lapse = withheld[i] ? 1 : config_.max_carried_frames;
      if (reference_[i] && ++carried_[i] <= lapse) {
        if (kept > 0) reference_uv_[i] += common / kept;
      } else {
        reference_[i] = false;
      }
    }
    return count;
  }

  // The frames in which marker i was withheld.
  std::uint64_t rejected(int i) const { return rejected_[static_cast<std::size_t>(i)]; }
  // The markers withheld from the frame stamped t_ns (unconfirmed ones too), if it was the last
  // one screened.
  std::array<bool, M> withheld_from(std::int64_t t_ns) const {
    return t_ns == last_t_ns_ ? last_withheld_ : std::array<bool, M>{};
  }

 private:
  // The largest set (bit i: marker i) of judged markers whose steps agree pairwise, if it holds
  // two or more and is the only one that large; else 0. At most 2^M sets: M is a few.
  unsigned agreeing_group(const std::array<bool, M>& judged,
                          const std::array<Eigen::Vector2d, M>& step) const {
    static_assert(M <= 16, "a few markers");
    std::array<unsigned, M> agrees{};  // bit j of agrees[i]: i's and j's steps agree
    unsigned candidates = 0;
    for (std::size_t i = 0; i < M; ++i) {
      if (!judged[i]) continue;
      candidates |= 1u << i;
      for (std::size_t j = 0; j < M; ++j)
        if (judged[j] && (step[i] - step[j]).norm() <= tolerance_px_) agrees[i] |= 1u << j;
    }
    unsigned best = 0;
    int best_size = 1, ties = 0;
    for (unsigned set = candidates; set != 0; set = (set - 1) & candidates) {  // its subsets
      const int size = __builtin_popcount(set);
      if (size < best_size) continue;
      bool clique = true;
      for (std::size_t i = 0; i < M && clique; ++i)
        if ((set & (1u << i)) != 0 && (agrees[i] & set) != set) clique = false;
      if (!clique) continue;
      if (size == best_size) {
        ++ties;
      } else {
        best = set;
        best_size = size;
        ties = 0;
      }
    }
    return best_size >= 2 && ties == 0 ? best : 0u;
  }

  MarkerScreenConfig config_;
  double tolerance_px_;
  bool has_frame_ = false;
  std::int64_t last_t_ns_ = 0;
  std::array<bool, M> reference_{};
  std::array<Eigen::Vector2d, M> reference_uv_;
  std::array<int, M> carried_{};
  std::array<bool, M> last_withheld_{};
  std::array<std::uint64_t, M> rejected_{};
};

}  // namespace mirrorcal::loop
