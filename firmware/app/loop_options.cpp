#include "loop_options.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>

#include "mirrorcal/firmware/realtime.hpp"

namespace mirrorcal::app {

const std::vector<std::string> kLoopValueOptions = {"budget-imu-us", "budget-frame-us",
                                                    "rt-priority", "cpu"};
const std::vector<std::string> kLoopFlagOptions = {"profile", "mlock"};

void apply_realtime_options(const Options& o) {
  firmware::RealtimeOptions rt;
  rt.fifo_priority = static_cast<int>(parse_count(o, "rt-priority", 0, 1));
  rt.lock_memory = o.flag("mlock");
  rt.cpu = o.flag("cpu") ? static_cast<int>(parse_count(o, "cpu", 0, 0)) : -1;
  const firmware::RealtimeOutcome r = firmware::apply_realtime(rt);
  if (!r.error.empty()) fail(r.error);
  for (const auto& note : r.notes) std::printf("real-time: %s\n", note.c_str());
}

std::unique_ptr<firmware::LoopProfiler> make_profiler(const Options& o, hal::Clock& clock,
                                                      std::int64_t imu_period_ns,
                                                      std::int64_t frame_period_ns) {
  const auto imu_us = parse_count(o, "budget-imu-us", 0, 1);
  const auto frame_us = parse_count(o, "budget-frame-us", 0, 1);
  if (!o.flag("profile")) {
    if (imu_us != 0 || frame_us != 0) fail("--budget-imu-us and --budget-frame-us need --profile");
    return nullptr;
  }
  return std::make_unique<firmware::LoopProfiler>(
      clock, imu_us != 0 ? static_cast<std::int64_t>(imu_us) * 1000 : imu_period_ns,
      frame_us != 0 ? static_cast<std::int64_t>(frame_us) * 1000 : frame_period_ns);
}

void report_profile(const firmware::LoopProfiler& p, const std::string& title,
                    const std::string& dir) {
  std::printf("\ntiming budget (%s):\n%s", title.c_str(), p.table().c_str());
  std::string err;
  const std::string path = dir + "/timing-histogram.txt";
  if (!p.write_histogram(path, err)) fail(err, 1);
  std::printf("wrote %s (cyclictest histogram format)\n", path.c_str());
}

Passes passes_option(const Options& o) {
  if (!o.flag("passes")) return Passes{};
  return Passes::exactly(static_cast<int>(parse_count(o, "passes", 0, 1, kMaxRequestedPasses)));
}

}  // namespace mirrorcal::app
