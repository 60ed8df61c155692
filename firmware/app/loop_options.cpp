#include "loop_options.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>

#include "mirrorcal/io/files.hpp"
#include "mirrorcal/loop/realtime.hpp"

namespace mirrorcal::app {

using namespace calibration;

const std::vector<std::string> kLoopValueOptions = {"budget-imu-us", "budget-frame-us",
                                                    "rt-priority", "cpu"};
const std::vector<std::string> kLoopFlagOptions = {"profile", "mlock"};

bool apply_realtime_options(const Options& o, std::string& error) {
  loop::RealtimeOptions rt;
  std::uint64_t priority = 0, cpu = 0;
  if (!parse_count(o, "rt-priority", 0, 1, priority, error)) return false;
  rt.fifo_priority = static_cast<int>(priority);
  rt.lock_memory = o.flag("mlock");
  if (o.flag("cpu") && !parse_count(o, "cpu", 0, 0, cpu, error)) return false;
  rt.cpu = o.flag("cpu") ? static_cast<int>(cpu) : -1;
  const loop::RealtimeOutcome r = loop::apply_realtime(rt);
  if (!r.error.empty()) {
    error = r.error;
    return false;
  }
  for (const auto& note : r.notes) std::printf("real-time: %s\n", note.c_str());
  return true;
}

bool make_profiler(const Options& o, hal::Clock& clock, std::int64_t imu_period_ns,
                   std::int64_t frame_period_ns, std::unique_ptr<loop::LoopProfiler>& profiler,
                   std::string& error) {
  std::uint64_t imu_us = 0, frame_us = 0;
  if (!parse_count(o, "budget-imu-us", 0, 1, imu_us, error) ||
      !parse_count(o, "budget-frame-us", 0, 1, frame_us, error))
    return false;
  if (!o.flag("profile")) {
    if (imu_us != 0 || frame_us != 0) {
      error = "--budget-imu-us and --budget-frame-us need --profile";
      return false;
    }
    profiler = nullptr;
    return true;
  }
  profiler = std::make_unique<loop::LoopProfiler>(
      clock, imu_us != 0 ? static_cast<std::int64_t>(imu_us) * 1000 : imu_period_ns,
      frame_us != 0 ? static_cast<std::int64_t>(frame_us) * 1000 : frame_period_ns);
  return true;
}

bool report_profile(const loop::LoopProfiler& p, const std::string& title, const std::string& dir,
                    std::string& error) {
  std::printf("\ntiming budget (%s):\n%s", title.c_str(), p.table().c_str());
  const std::string path = dir + "/timing-histogram.txt";
  io::OutputSet out;
  std::FILE* f = out.add(path, error);
  if (f == nullptr) return false;
  p.write_histogram(f);
  if (!out.commit(error)) return false;
  std::printf("wrote %s (cyclictest histogram format)\n", path.c_str());
  return true;
}

bool passes_option(const Options& o, Passes& passes, std::string& error) {
  if (!o.flag("passes")) {
    passes = Passes{};
    return true;
  }
  std::uint64_t n = 0;
  if (!parse_count(o, "passes", 0, 1, n, error, kMaxRequestedPasses)) return false;
  passes = Passes::exactly(static_cast<int>(n));
  return true;
}

}  // namespace mirrorcal::app
