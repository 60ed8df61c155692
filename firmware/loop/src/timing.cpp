#include "mirrorcal/loop/timing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

namespace mirrorcal::loop {

const char* stage_name(Stage s) {
  switch (s) {
    case Stage::kImuWait:
      return "imu_wait";
    case Stage::kImuRead:
      return "imu_read";
    case Stage::kPropagation:
      return "propagation";
    case Stage::kFrameWait:
      return "frame_wait";
    case Stage::kMarkerDetection:
      return "detection";
    case Stage::kUpdate:
      return "update";
    case Stage::kOutput:
      return "output";
    case Stage::kImuPath:
      return "imu_path";
    case Stage::kFramePath:
      return "frame_path";
    case Stage::kCount:
      break;
  }
  return "?";
}

void DurationHistogram::add(std::int64_t ns) {
  ns = std::max<std::int64_t>(ns, 0);
  const std::int64_t us = ns / 1000;
  if (us < kBins)
    ++bins_[static_cast<std::size_t>(us)];
  else
    ++overflows_;
  if (count_ == 0 || ns < min_ns_) min_ns_ = ns;
  max_ns_ = std::max(max_ns_, ns);
  sum_ns_ += ns;
  ++count_;
  if (budget_ns_ > 0 && ns > budget_ns_) ++misses_;
}

double DurationHistogram::quantile_us(double q) const {
  if (count_ == 0) return 0.0;
  // The smallest bin whose cumulative count reaches ceil(q * count).
  const auto rank = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (int i = 0; i < kBins; ++i) {
    seen += bins_[static_cast<std::size_t>(i)];
    if (seen >= rank && seen > 0) return std::min(double(i + 1), double(max_ns_) * 1e-3);
  }
  return double(max_ns_) * 1e-3;
}

LoopProfiler::LoopProfiler(hal::Clock& clock, std::int64_t imu_budget_ns,
                           std::int64_t frame_budget_ns)
    : clock_(clock) {
  hist_[index(Stage::kImuPath)].set_budget(imu_budget_ns);
  hist_[index(Stage::kFramePath)].set_budget(frame_budget_ns);
}

void LoopProfiler::record(Stage s, std::int64_t ns) {
  hist_[index(s)].add(ns);
  (in_frame_ ? frame_total_ns_ : imu_total_ns_) += ns;
}

void LoopProfiler::imu_read(std::int64_t ns, std::int64_t wait_ns) {
  wait_ns = std::clamp<std::int64_t>(wait_ns, 0, ns);
  hist_[index(Stage::kImuWait)].add(wait_ns);
  record(Stage::kImuRead, ns - wait_ns);
}

void LoopProfiler::marker_polled(std::int64_t ns, std::int64_t detection_ns) {
  if (detection_ns < 0) {
    record(Stage::kFrameWait, ns);
    return;
  }
  detection_ns = std::min(detection_ns, ns);
  hist_[index(Stage::kFrameWait)].add(ns - detection_ns);
  hist_[index(Stage::kMarkerDetection)].add(detection_ns);
  frame_total_ns_ += ns;
}

void LoopProfiler::close_path(Stage path, std::int64_t& total) {
  hist_[index(path)].add(total);
  total = 0;
}

void LoopProfiler::end_frame() {
  close_path(Stage::kFramePath, frame_total_ns_);
  in_frame_ = false;
}

void LoopProfiler::end_imu_sample() {
  close_path(Stage::kImuPath, imu_total_ns_);
}

StageReport LoopProfiler::report(Stage s) const {
  const DurationHistogram& h = hist_[index(s)];
  StageReport r;
  r.stage = s;
  r.count = h.count();
  r.min_us = double(h.min_ns()) * 1e-3;
  r.median_us = h.quantile_us(0.5);
  r.p99_us = h.quantile_us(0.99);
  r.p999_us = h.quantile_us(0.999);
  r.max_us = double(h.max_ns()) * 1e-3;
  r.mean_us = h.mean_ns() * 1e-3;
  r.budget_ns = h.budget_ns();
  r.misses = h.misses();
  return r;
}

std::string LoopProfiler::table() const {
  std::string out;
  char line[256];
  std::snprintf(line, sizeof line, "%-12s %9s %9s %9s %9s %9s %10s %10s %9s\n", "stage", "count",
                "min us", "median us", "p99 us", "p99.9 us", "max us", "budget us", "misses");
  out += line;
  for (std::size_t i = 0; i < hist_.size(); ++i) {
    const StageReport r = report(static_cast<Stage>(i));
    if (r.count == 0) continue;
    char budget[32] = "-", misses[32] = "-";
    if (r.budget_ns > 0) {
      std::snprintf(budget, sizeof budget, "%.0f", double(r.budget_ns) * 1e-3);
      std::snprintf(misses, sizeof misses, "%llu", static_cast<unsigned long long>(r.misses));
    }
    std::snprintf(line, sizeof line, "%-12s %9llu %9.1f %9.0f %9.0f %9.0f %10.1f %10s %9s\n",
                  stage_name(r.stage), static_cast<unsigned long long>(r.count), r.min_us,
                  r.median_us, r.p99_us, r.p999_us, r.max_us, budget, misses);
    out += line;
  }
  out += "(quantiles are upper edges of 1 us bins)\n";
  return out;
}

// The layout of cyclictest -h (rt-tests' print_hist): one line per bin, one column per "thread"
// (here per stage), then the summary lines. Lines starting with # are comments to its readers.
void LoopProfiler::write_histogram(std::FILE* f) const {
  const std::size_t n = hist_.size();
  std::fprintf(f, "# mirrorcal loop timing, 1 us bins; columns (cyclictest threads):");
  for (std::size_t j = 0; j < n; ++j) std::fprintf(f, " %s", stage_name(static_cast<Stage>(j)));
  std::fprintf(f, "\n# Histogram\n");
  for (int i = 0; i < DurationHistogram::kBins; ++i) {
    std::fprintf(f, "%06d ", i);
    for (std::size_t j = 0; j < n; ++j)
      std::fprintf(f, j + 1 < n ? "%06llu\t" : "%06llu\n",
                   static_cast<unsigned long long>(hist_[j].bin(i)));
  }
  auto summary = [&](const char* title, const char* fmt, auto value) {
    std::fprintf(f, "# %s:", title);
    for (std::size_t j = 0; j < n; ++j) std::fprintf(f, fmt, value(hist_[j]));
    std::fprintf(f, "\n");
  };
  using H = DurationHistogram;
  using ull = unsigned long long;
  summary("Total", " %09llu", [](const H& h) { return ull(h.count()); });
  summary("Min Latencies", " %05llu", [](const H& h) { return ull(h.min_ns() / 1000); });
  summary("Avg Latencies", " %05llu", [](const H& h) { return ull(h.mean_ns() / 1000); });
  summary("Max Latencies", " %05llu", [](const H& h) { return ull(h.max_ns() / 1000); });
  summary("Histogram Overflows", " %05llu", [](const H& h) { return ull(h.overflows()); });
  std::fprintf(f, "# Histogram Overflow at cycle number:\n");
  for (std::size_t j = 0; j < n; ++j) {
    std::fprintf(f, "# Thread %zu:", j);
    if (hist_[j].overflows() > 0) std::fprintf(f, " # %05llu others", ull(hist_[j].overflows()));
    std::fprintf(f, "\n");
  }
  std::fprintf(f, "\n");
}

std::int64_t SteadyClock::now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace mirrorcal::loop
