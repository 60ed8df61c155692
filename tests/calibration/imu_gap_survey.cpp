// The README's IMU-gap figures over more rigs than imu_gap_tests take: for each random-family rig
// FIRST..LAST and each gap, the calibration with the IMU silent for that long from START_MS (0: no
// gap), one line each: NEES, the worst state in sigmas, whether the self-check passed it, and the
// markers gated and the normalised innovation squared per dof in the 0.5 s after the gap.
//   imu_gap_survey FIRST LAST START_MS GAP_MS...   (ONCE=1: one pass, no refinement;
//                                                   NOREFINE=1: the free passes alone)
#include <cstdio>
#include <cstdlib>
#include <string>

#include "imu_gap_run.hpp"
#include "mirrorcal/calibration/result.hpp"

namespace mc = mirrorcal;
using mc::gaptest::kMs;
using mc::gaptest::Run;

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: imu_gap_survey FIRST LAST START_MS GAP_MS...\n");
    return 2;
  }
  const std::uint64_t first = std::stoull(argv[1]), last = std::stoull(argv[2]);
  const std::int64_t start_ms = std::stoll(argv[3]);
  const mc::calibration::Passes passes =
      std::getenv("ONCE") != nullptr       ? mc::calibration::Passes::once()
      : std::getenv("NOREFINE") != nullptr ? mc::calibration::Passes{2, 4, false}
                                           : mc::calibration::Passes{};
  for (std::uint64_t seed = first; seed <= last; ++seed) {
    const mc::sim::Scenario s = mc::sim::random_scenario(seed);
    for (int i = 4; i < argc; ++i) {
      const std::int64_t gap_ms = std::stoll(argv[i]);
      const Run run = mc::gaptest::calibrate_with_gap(s, seed, start_ms, gap_ms, passes);
      const std::int64_t after = (start_ms + gap_ms) * kMs;
      int gated = 0, dof = 0;
      double nis = 0.0;
      for (const auto& row : run.history) {
        if (row.t_ns < after || row.t_ns > after + 500 * kMs) continue;
        gated += row.markers_gated;
        nis += row.nis;
        dof += row.nis_dof;
      }
      std::printf(
          "seed %llu %s gap_ms %lld nees %.2f worst_sigmas %.2f consistent %d restarts %llu "
          "after_gated %d after_nis_per_dof %.3f\n",
          static_cast<unsigned long long>(seed), s.motion_kind.c_str(),
          static_cast<long long>(gap_ms), run.history.back().nees, mc::gaptest::worst_sigmas(run),
          mc::calibration::consistent(run.result) ? 1 : 0,
          static_cast<unsigned long long>(run.loop_counters.imu_restarts), gated,
          dof > 0 ? nis / dof : 0.0);
      std::fflush(stdout);
    }
  }
  return 0;
}
