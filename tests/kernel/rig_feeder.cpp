// The simulated rig as live devices for `mirrorcal run` on a real kernel, and the check of what the
// run wrote against the rig's truth:
//
//   rig_feeder play SCENARIO SEED SECONDS
//     Sets vivid up as a loop-back camera (vivid_setup.hpp), simulates the rig (the same data as
//     `mirrorcal record --scenario SCENARIO --seed SEED`), writes /tmp/feeder-ready and waits for
//     /tmp/go; then, in real time for SECONDS, sends its IMU samples as Bosch MM7.10 frames on
//     vcan0 and writes its rendered mirror frames to vivid's output, so that mirrorcal reads them
//     from vivid's capture as from a camera.
//   rig_feeder check SCENARIO DIR K
//     Reads DIR/camchain-imucam.yaml (T_cam_imu) and DIR/mirrorcal-result.yaml (the markers and
//     the 1-sigma of every calibration state) and checks each error against the truth within K
//     reported sigmas, and that the camera rotation and the markers were learnt (their sigmas
//     well below the prior's).
//
// A frame's timestamp is vivid's: the time its capture thread copies the output's current frame,
// plus 0.9 of a frame period (vivid stamps the end of the frame). Rather than queue frames, whose
// capture time nobody outside vivid knows to better than a frame period, the feeder keeps one
// output frame queued, which vivid shows for good, and redraws its spots in place every half
// millisecond for the time a capture taken then will be stamped with (see
// V4l2Output::last_written_data). The IMU thread and the redraws run as real-time tasks: they
// stand for hardware, which does not wait for the program under test.
#include <pthread.h>
#include <sched.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "guest_check.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/v4l2.hpp"
#include "mirrorcal/estimator/so3.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"
#include "vcan_sender.hpp"
#include "vivid_setup.hpp"

namespace {

using namespace mirrorcal;

bool exists(const char* path) {
  return std::ifstream(path).good();
}

bool scenario_arg(const char* name, std::uint64_t seed, sim::Scenario& s) {
  if (sim::scenario_by_name(name, seed, s)) return true;
  std::printf("rig_feeder: unknown scenario '%s'\n", name);
  return false;
}

// The IMU stream in real time: sample i at t0 + (its time - the first's). Returns the largest
// lateness of a send (ns).
std::int64_t play_imu(const std::vector<ImuSample>& imu, std::int64_t t0, std::int64_t end_ns,
                      int fd, std::atomic<bool>& failed) {
  drivers::CanImuSender sender(fd);
  std::int64_t late = 0;
  for (const ImuSample& s : imu) {
    const std::int64_t at = t0 + s.t_ns - imu.front().t_ns;
    if (at > end_ns) break;
    drivers::sleep_until_ns(at);
    late = std::max(late, drivers::monotonic_ns() - at);
    if (!sender.send(s)) {
      std::printf("rig_feeder: CAN send failed: %s\n", std::strerror(errno));
      failed = true;
      break;
    }
  }
  return late;
}

// Runs the calling thread as a real-time task: the feeder stands for hardware, which does not
// wait for the program under test.
void realtime(int priority) {
  sched_param p{};
  p.sched_priority = priority;
  if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &p) != 0)
    std::printf("rig_feeder: no SCHED_FIFO (%s); timing will suffer\n", std::strerror(errno));
}

int play(const sim::Scenario& s, std::uint64_t seed, double seconds) {
  if (!guest::configure_vivid(true, 0)) return guest::finish("rig_feeder play");
  const sim::SimData data = sim::simulate(s, seed);
  sim::FrameRenderer renderer(s, sim::RenderConfig{}, seed);
  const auto size = static_cast<std::size_t>(renderer.bytes_per_line() * renderer.height());
  std::vector<std::uint8_t> still(size);
  renderer.finish(0, still.data());  // the scene with no spot in view
  const int can = guest::open_sender("vcan0");
  drivers::V4l2Output out;
  if (!GUEST_CHECK(can >= 0) ||
      !GUEST_CHECK(out.open(guest::kVividOutput, guest::vivid_config(hal::PixelFormat::kGrey))) ||
      !GUEST_CHECK(out.bytes_per_line() == renderer.bytes_per_line())) {
    std::printf("%s\n", out.error());
    return guest::finish("rig_feeder play");
  }
  const std::int64_t period = out.frame_period_ns() > 0 ? out.frame_period_ns() : 16'683'350;
  // Two frames queued (vivid starts with two); vivid retires the first at its first tick and
  // keeps showing the second, the last one, for good: the frame drawn into from then on.
  const int free0 = out.free_buffers();
  if (!GUEST_CHECK(out.write(still.data(), renderer.bytes_per_line(), 0) &&
                   out.write(still.data(), renderer.bytes_per_line(), 0) && out.start())) {
    std::printf("%s\n", out.error());
    return guest::finish("rig_feeder play");
  }
  std::uint8_t* shown = out.last_written_data();
  const std::int64_t deadline = drivers::monotonic_ns() + 5'000'000'000;
  while (out.free_buffers() != free0 - 1 && drivers::monotonic_ns() < deadline)
    drivers::sleep_until_ns(drivers::monotonic_ns() + 1'000'000);
  if (!GUEST_CHECK(out.free_buffers() == free0 - 1)) return guest::finish("rig_feeder play");
  sim::RenderedTruth truth;
  renderer.update_spots(data.imu.front().t_ns, still.data(), shown, truth);  // at rest
  std::fclose(std::fopen("/tmp/feeder-ready", "w"));
  while (!exists("/tmp/go")) drivers::sleep_until_ns(drivers::monotonic_ns() + 20'000'000);

  const std::int64_t t0 = drivers::monotonic_ns() + 50'000'000;
  const std::int64_t end = t0 + static_cast<std::int64_t>(seconds * 1e9);
  std::atomic<bool> can_failed{false};
  std::int64_t imu_late = 0;
  std::thread imu([&] {
    realtime(60);
    imu_late = play_imu(data.imu, t0, end, can, can_failed);
  });

  // The shown frame follows the clock: redrawn every 0.5 ms with the rig as it will be at
  // the timestamp vivid gives a capture taken now (0.9 of a period later: vivid stamps the end of
  // the frame), half the wait until the next redraw on.
  realtime(50);
  constexpr std::int64_t kRedraw = 500'000;
  const std::int64_t stamp_offset = 9 * period / 10 + kRedraw / 2;
  std::uint64_t redraws = 0;
  double draw_s = 0.0;
  std::int64_t next = t0;
  while (!can_failed) {
    drivers::sleep_until_ns(next);
    const std::int64_t now = drivers::monotonic_ns();
    if (now > end) break;
    renderer.update_spots(now + stamp_offset - t0 + data.imu.front().t_ns, still.data(), shown,
                          truth);
    draw_s += 1e-9 * static_cast<double>(drivers::monotonic_ns() - now);
    if (++redraws % 256 == 0 && !GUEST_CHECK(out.free_buffers() == free0 - 1)) break;
    next = std::max(next + kRedraw, now);
  }
  imu.join();
  std::printf(
      "rig_feeder: %.1f s played: the frame redrawn %llu times (%.2f ms each), IMU sends at most "
      "%.1f ms late\n",
      seconds, static_cast<unsigned long long>(redraws),
      redraws > 0 ? 1e3 * draw_s / static_cast<double>(redraws) : 0.0,
      1e-6 * static_cast<double>(imu_late));
  GUEST_CHECK(!can_failed);
  GUEST_CHECK(redraws > 0);
  return guest::finish("rig_feeder play");
}

// The four numbers of a "- [a, b, c, d]" row (three when d is null).
bool read_row(std::ifstream& in, double* v, int n) {
  std::string line;
  if (!std::getline(in, line)) return false;
  const char* p = std::strchr(line.c_str(), '[');
  for (int i = 0; i < n; ++i) {
    if (p == nullptr) return false;
    char* end = nullptr;
    v[i] = std::strtod(p + 1, &end);
    if (end == p + 1) return false;
    p = std::strchr(end, ',');
    if (i + 1 < n && p == nullptr) return false;
  }
  return true;
}

// Skips to the line that starts (after indentation) with key.
// Reads up to the line starting with key; with value, the number after the key.
bool seek(std::ifstream& in, const std::string& key, double* value = nullptr) {
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t start = line.find_first_not_of(' ');
    if (start == std::string::npos || line.compare(start, key.size(), key) != 0) continue;
    if (value != nullptr) *value = std::strtod(line.c_str() + start + key.size(), nullptr);
    return true;
  }
  return false;
}

int check(const sim::Scenario& s, const std::string& dir, double k) {
  // T_cam_imu maps IMU coordinates into the camera's: R_c_b and t = -R_c_b p_b_c.
  std::ifstream camchain(dir + "/camchain-imucam.yaml");
  Eigen::Matrix4d t_cam_imu;
  bool ok = GUEST_CHECK(seek(camchain, "T_cam_imu:"));
  for (int r = 0; r < 4 && ok; ++r) {
    double row[4];
    ok = GUEST_CHECK(read_row(camchain, row, 4));
    for (int c = 0; c < 4; ++c) t_cam_imu(r, c) = row[c];
  }
  std::ifstream result(dir + "/mirrorcal-result.yaml");
  std::vector<Eigen::Vector3d> markers(s.truth.markers.size());
  ok = ok && GUEST_CHECK(seek(result, "features_c:"));
  for (auto& m : markers) ok = ok && GUEST_CHECK(read_row(result, m.data(), 3));
  std::vector<double> sigma;
  std::vector<std::string> names;
  ok = ok && GUEST_CHECK(seek(result, "sigma:"));
  std::string line;
  while (ok && std::getline(result, line)) {
    const std::size_t colon = line.find(':');
    if (colon == std::string::npos) break;
    names.push_back(line.substr(line.find_first_not_of(' '), colon - line.find_first_not_of(' ')));
    sigma.push_back(std::strtod(line.c_str() + colon + 1, nullptr));
  }
  // p_b_c, rotation, markers, then the time offset, which has no truth here: the live camera's
  // end-of-frame stamps and the loop-back's latency make it. It is reported, and must be learnt.
  const CalibrationLayout layout = calibration_layout(static_cast<int>(markers.size()), 0);
  if (!ok || !GUEST_CHECK(sigma.size() == static_cast<std::size_t>(layout.size())) ||
      !GUEST_CHECK(names.back() == "timeshift_cam_imu"))
    return guest::finish("rig_feeder check");
  const double sigma_t_d = sigma.back();
  sigma.pop_back();
  names.pop_back();
  double t_d = 0.0;
  std::ifstream again(dir + "/mirrorcal-result.yaml");
  GUEST_CHECK(seek(again, "timeshift_cam_imu:", &t_d));
  std::printf("time offset found: %.3f ms +- %.3f ms (the camera's stamps against the IMU's)\n",
              1e3 * t_d, 1e3 * sigma_t_d);
  GUEST_CHECK(sigma_t_d < 0.5 * s.priors.time_offset);

  const Eigen::Matrix3d r_b_c = t_cam_imu.topLeftCorner<3, 3>().transpose();
  const Eigen::Vector3d p_b_c = -r_b_c * t_cam_imu.topRightCorner<3, 1>();
  // Errors in the filter's convention: rotation R = R_true Exp(e).
  std::vector<double> error(sigma.size());
  const Eigen::Vector3d dp = p_b_c - s.truth.p_b_c;
  const Eigen::Vector3d de =
      so3::log<double>(s.truth.q_b_c.conjugate() * Eigen::Quaterniond(r_b_c).normalized());
  for (int i = 0; i < 3; ++i) {
    error[static_cast<std::size_t>(i)] = dp[i];
    error[static_cast<std::size_t>(3 + i)] = de[i];
  }
  for (std::size_t m = 0; m < markers.size(); ++m)
    for (int i = 0; i < 3; ++i)
      error[static_cast<std::size_t>(layout[CalibrationGroup::kMarkers].begin + 3 * int(m) + i)] =
          markers[m][i] - s.truth.markers[m][i];

  std::printf("%-8s %12s %12s %8s   (SI: m, rad)\n", "state", "error", "1-sigma", "err/sig");
  for (std::size_t j = 0; j < sigma.size(); ++j) {
    std::printf("%-8s %+12.6f %12.6f %+8.2f\n", names[j].c_str(), error[j], sigma[j],
                error[j] / sigma[j]);
    GUEST_CHECK(sigma[j] > 0 && std::fabs(error[j]) <= k * sigma[j]);
  }
  // Learnt, not only consistent: the camera rotation and the markers known far better than the
  // prior said.
  for (std::size_t j = 3; j < sigma.size(); ++j)
    GUEST_CHECK(sigma[j] < 0.5 * (j < 6 ? s.priors.rot_b_c : s.priors.marker));
  return guest::finish("rig_feeder check");
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  sim::Scenario s;
  const std::uint64_t seed = argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 0;
  if (mode == "play" && argc == 5 && scenario_arg(argv[2], seed, s))
    return play(s, seed, std::atof(argv[4]));
  if (mode == "check" && argc == 5 && scenario_arg(argv[2], 0, s))
    return check(s, argv[3], std::atof(argv[4]));
  std::printf("usage: rig_feeder play SCENARIO SEED SECONDS | check SCENARIO DIR K\n");
  return 2;
}
