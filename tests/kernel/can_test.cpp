// CAN on a real kernel (vcan0, can-raw): the simulated rig's IMU stream, sent as Bosch MM7.10
// frames, comes back through the project's CAN driver decoded to the bit; a lost frame, a bus-off
// error frame and garbage frames are counted and survived; can-utils' cansend and candump act as
// an independent peer in both directions.
#include <linux/can.h>
#include <linux/can/error.h>
#include <net/if.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "guest_check.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/sim/scenario.hpp"
#include "mirrorcal/sim/simulator.hpp"
#include "vcan_sender.hpp"

namespace {

using namespace mirrorcal;
using namespace mirrorcal::drivers;

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;
constexpr double kRateBit = 0.005 * kPi / 180;  // the layout's steps, in SI
constexpr double kAccelBit = 0.000127465 * kG;

void write_raw(int fd, canid_t id, std::uint8_t len) {
  can_frame f{};
  f.can_id = id;
  f.len = len;
  GUEST_CHECK(write(fd, &f, sizeof(f)) == static_cast<ssize_t>(sizeof(f)));
}

// The value the layout carries for v: v rounded to the nearest step.
double on_the_wire(double v, double step) {
  return std::round(v / step) * step;
}

bool same(double a, double b) {
  return std::fabs(a - b) <= 1e-12 * (1 + std::fabs(b));
}

void check_decoded_exactly(const ImuSample& in, const ImuSample& out) {
  for (int k = 0; k < 3; ++k) {
    GUEST_CHECK(same(out.gyro[k], on_the_wire(in.gyro[k], kRateBit)));
    GUEST_CHECK(same(out.accel[k], on_the_wire(in.accel[k], kAccelBit)));
  }
}

// Sends a sample's three frames with the sensor's message counter, leaving out frame `skip`.
void send_sample(CanImuSender& bus, const ImuSample& s, std::uint8_t& counter, int skip = -1) {
  mm710::Frame f[3];
  GUEST_CHECK(mm710::encode(s, counter, f));  // the rig stays within the sensor's range
  counter = static_cast<std::uint8_t>((counter + 1) & 0x0f);
  for (int m = 0; m < 3; ++m)
    if (m != skip) GUEST_CHECK(bus.send_frame(f[m]));
}

void simulated_stream(CanImu& imu, CanImuSender& bus, int tx, std::uint8_t& counter) {
  sim::Scenario scenario = sim::paper_scenario();
  scenario.duration_s = 10.5;
  const sim::SimData data = sim::simulate(scenario, 11);
  const std::size_t n = 2000;  // 10 s of the rig at 200 Hz
  GUEST_CHECK(data.imu.size() >= n);
  std::int64_t last_t = 0;
  std::size_t exact = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t before = monotonic_ns();
    if (i == 700) {
      // A lost frame: TX2 of this sample never makes it onto the bus; the driver drops the
      // sample and returns the next one.
      send_sample(bus, data.imu[i], counter, 1);
      ++i;
    } else if (i == 1200) {
      // The bus goes off and comes back: an error frame as a controller would report it.
      write_raw(tx, CAN_ERR_FLAG | CAN_ERR_BUSOFF, CAN_ERR_DLC);
    } else if (i == 1500) {
      write_raw(tx, mm710::kTx1, 3);                 // our id, wrong length: the driver rejects it
      write_raw(tx, 0x123, 8);                       // others' traffic: the kernel filter drops it
      write_raw(tx, mm710::kTx2 | CAN_EFF_FLAG, 8);  // extended id: dropped by the filter
      write_raw(tx, mm710::kTx3 | CAN_RTR_FLAG, 0);  // remote request: dropped by the filter
    }
    send_sample(bus, data.imu[i], counter);
    ImuSample out;
    if (!GUEST_CHECK(imu.next(out) == hal::SourceStatus::kOk)) {
      std::printf("  %s\n", imu.error());
      return;
    }
    const ImuSample& expected = data.imu[i];
    check_decoded_exactly(expected, out);
    exact += 1;
    // Receive times on the loop's clock (CLOCK_MONOTONIC), not CLOCK_REALTIME.
    GUEST_CHECK(out.t_ns >= before && out.t_ns <= monotonic_ns());
    GUEST_CHECK(out.t_ns > last_t);
    last_t = out.t_ns;
  }
  const CanImuCounters& c = imu.counters();
  std::printf(
      "stream: %zu samples decoded, frames %llu, lost %llu, incomplete %llu, rejected %llu, "
      "error frames %llu, bus-off %llu, recoveries %llu\n",
      exact, static_cast<unsigned long long>(c.frames),
      static_cast<unsigned long long>(c.lost_frames()),
      static_cast<unsigned long long>(c.assembly.incomplete_samples),
      static_cast<unsigned long long>(c.rejected_frames),
      static_cast<unsigned long long>(c.error_frames), static_cast<unsigned long long>(c.bus_off),
      static_cast<unsigned long long>(c.recoveries));
  GUEST_CHECK(c.lost_frames() == 1 && c.assembly.lost_frames[1] == 1);
  GUEST_CHECK(c.assembly.incomplete_samples == 1);
  GUEST_CHECK(c.rejected_frames == 1);
  GUEST_CHECK(c.error_frames == 1 && c.bus_off == 1 && c.recoveries == 1);
  GUEST_CHECK(std::strcmp(imu.last_bus_error(), "bus-off") == 0);
  GUEST_CHECK(c.samples == n - 1);
}

// cansend as the sensor: three frames written by hand from the layout table.
void cansend_peer(CanImu& imu, std::uint8_t counter) {
  char cmd[160];
  // TX1: yaw +10 deg/s (0x87D0), AY +1 g (0x8000 + 7845 = 0x9EA5); TX2: roll sent -10 deg/s
  // (0x7830, i.e. +10 deg/s right-handed), AX -0.5 g (0x8000 - 3923 = 0x70AD); TX3: pitch -2 deg/s
  // (0x7E70), AZ 0 (0x8000).
  const char* frames[3] = {"174#D0870000A59E%02X00", "178#30780000AD70%02X00",
                           "17C#707E00000080%02X00"};
  for (const char* f : frames) {
    std::snprintf(cmd, sizeof(cmd), "cansend vcan0 ");
    std::snprintf(cmd + std::strlen(cmd), sizeof(cmd) - std::strlen(cmd), f, counter & 0x0f);
    GUEST_CHECK(std::system(cmd) == 0);
  }
  ImuSample out;
  if (!GUEST_CHECK(imu.next(out) == hal::SourceStatus::kOk)) return;
  const double dps = kPi / 180;
  GUEST_CHECK(same(out.gyro.x(), 2000 * 0.005 * dps));
  GUEST_CHECK(same(out.gyro.y(), -400 * 0.005 * dps));
  GUEST_CHECK(same(out.gyro.z(), 2000 * 0.005 * dps));
  GUEST_CHECK(same(out.accel.x(), -3923 * 0.000127465 * kG));
  GUEST_CHECK(same(out.accel.y(), 7845 * 0.000127465 * kG));
  GUEST_CHECK(same(out.accel.z(), 0.0));
  std::printf("cansend: decoded gyro %.6f %.6f %.6f rad/s, accel %.6f %.6f %.6f m/s^2\n",
              out.gyro.x(), out.gyro.y(), out.gyro.z(), out.accel.x(), out.accel.y(),
              out.accel.z());
}

// candump as the listener: our sender's frames on the wire, byte for byte, against the table.
void candump_peer(CanImuSender& sender) {
  FILE* dump = popen("candump -L -n 3 vcan0,174:7FF,178:7FF,17C:7FF", "r");
  if (!GUEST_CHECK(dump != nullptr)) return;
  usleep(300'000);  // candump has bound its socket
  const std::uint8_t counter = sender.counter();
  const double dps = kPi / 180;
  ImuSample s;
  s.gyro = Eigen::Vector3d(10 * dps, -2 * dps, 10 * dps);
  s.accel = Eigen::Vector3d(-0.5 * kG, 1 * kG, 0);
  GUEST_CHECK(sender.send(s));
  char expected[3][40];
  std::snprintf(expected[0], 40, "174#D087004BA59E%02X00", counter);  // 0x4B: 25 degC
  std::snprintf(expected[1], 40, "178#30780000AD70%02X00", counter);
  std::snprintf(expected[2], 40, "17C#707E00000080%02X00", counter);
  char line[200];
  for (int i = 0; i < 3; ++i) {
    if (!GUEST_CHECK(std::fgets(line, sizeof(line), dump) != nullptr)) break;
    // "(seconds.micros) vcan0 174#..."
    const char* frame = std::strstr(line, "vcan0 ");
    GUEST_CHECK(frame != nullptr && std::strncmp(frame + 6, expected[i], 20) == 0);
    std::printf("candump: %s", line);
  }
  GUEST_CHECK(pclose(dump) == 0);
}

// `guest_can send SECONDS`: the simulated rig as a live MM7.10 on vcan0, in real time (the peer
// of `mirrorcal run` in kernel_run_can).
int send_live(double seconds) {
  const int tx = guest::open_sender("vcan0");
  if (tx < 0) return 1;
  sim::Scenario scenario = sim::paper_scenario();
  scenario.duration_s = seconds + 0.1;
  const sim::SimData data = sim::simulate(scenario, 12);
  CanImuSender sender(tx);
  std::fclose(std::fopen("/tmp/sender-ready", "w"));  // simulated: the listener may start
  const std::int64_t t0 = monotonic_ns();
  for (const ImuSample& s : data.imu) {
    sleep_until_ns(t0 + s.t_ns - data.imu.front().t_ns);
    if (!sender.send(s)) return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "send") == 0) return send_live(std::atof(argv[2]));
  try {
    CanImu imu(open_mm710_socket("vcan0"), "vcan0", 1'000'000'000);
    const int tx = guest::open_sender("vcan0");
    if (!GUEST_CHECK(tx >= 0)) return mirrorcal::guest::finish("kernel CAN");
    CanImuSender sender(tx);
    std::uint8_t counter = 0;
    simulated_stream(imu, sender, tx, counter);
    cansend_peer(imu, counter);
    candump_peer(sender);
    // Errors a user meets: no such interface, and a non-CAN one.
    for (const char* name : {"can7", "lo"}) {
      try {
        open_mm710_socket(name);
        GUEST_CHECK(!"opened");
      } catch (const DriverError& e) {
        std::printf("open %s: %s\n", name, e.what());
        GUEST_CHECK(e.fault() ==
                    (std::strcmp(name, "lo") == 0 ? Fault::kWrongKind : Fault::kMissing));
      }
    }
  } catch (const DriverError& e) {
    std::printf("FAILED: %s\n", e.what());
    return 1;
  }
  return mirrorcal::guest::finish("kernel CAN");
}
