// The MM7.10 frame layout, the assembly of samples from frames with its loss accounting, and the
// CAN IMU source on a socket pair that carries struct can_frame records like a CAN_RAW socket.
#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmath>
#include <random>

#include "fakes.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"

namespace mirrorcal::drivers {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.80665;
constexpr double kRateBit = 0.005 * kPi / 180;  // rad/s per bit
constexpr double kAccelBit = 0.000127465 * kG;  // m/s^2 per bit

ImuSample sample_of(double gx, double gy, double gz, double ax, double ay, double az) {
  ImuSample s;
  s.gyro = Eigen::Vector3d(gx, gy, gz);
  s.accel = Eigen::Vector3d(ax, ay, az);
  return s;
}

TEST(Mm710, FramesMatchTheLayoutWorkedByHand) {
  const double dps = kPi / 180;
  mm710::Frame f[3];
  ASSERT_TRUE(mm710::encode(sample_of(10 * dps, -2 * dps, 10 * dps, -0.5 * kG, 1 * kG, 0), 5, f));
  // TX1 0x174: yaw +10 deg/s = 0x8000 + 2000 = 0x87D0; AY 1 g = 0x8000 + 7845 = 0x9EA5.
  EXPECT_EQ(f[0].id, 0x174u);
  EXPECT_EQ(f[0].data[0], 0xD0);
  EXPECT_EQ(f[0].data[1], 0x87);
  EXPECT_EQ(f[0].data[4], 0xA5);
  EXPECT_EQ(f[0].data[5], 0x9E);
  EXPECT_EQ(f[0].data[6] & 0x0f, 5) << "message counter in bits 48-51";
  // TX2 0x178: roll is sent against the right-hand rule: +10 deg/s goes out as -10 = 0x7830;
  // AX -0.5 g = 0x8000 - 3923 (3922.6 rounded) = 0x70AD.
  EXPECT_EQ(f[1].id, 0x178u);
  EXPECT_EQ(f[1].data[0], 0x30);
  EXPECT_EQ(f[1].data[1], 0x78);
  EXPECT_EQ(f[1].data[4], 0xAD);
  EXPECT_EQ(f[1].data[5], 0x70);
  // TX3 0x17C: pitch -2 deg/s = 0x8000 - 400 = 0x7E70; AZ 0 = 0x8000.
  EXPECT_EQ(f[2].id, 0x17Cu);
  EXPECT_EQ(f[2].data[0], 0x70);
  EXPECT_EQ(f[2].data[1], 0x7E);
  EXPECT_EQ(f[2].data[4], 0x00);
  EXPECT_EQ(f[2].data[5], 0x80);
  for (const auto& frame : f) EXPECT_EQ(frame.len, 8);
}

// The CRC byte (bits 56-63) is carried but not verified: no public source gives the MM7.10's
// algorithm (can_imu.hpp). The sender writes 0; the decoder reads the same values whatever it
// holds.
TEST(Mm710, TheCrcByteIsCarriedNotVerified) {
  const double dps = kPi / 180;
  mm710::Frame f[3];
  ASSERT_TRUE(mm710::encode(sample_of(3 * dps, -1 * dps, 7 * dps, 0.2 * kG, -0.1 * kG, kG), 9, f));
  for (int m = 0; m < 3; ++m) {
    EXPECT_EQ(f[m].data[7], 0) << "message " << m;
    mm710::Part zero, other;
    ASSERT_TRUE(mm710::decode(f[m], zero));
    for (const int crc : {0x01, 0x5a, 0xff}) {
      mm710::Frame g = f[m];
      g.data[7] = static_cast<std::uint8_t>(crc);
      ASSERT_TRUE(mm710::decode(g, other)) << "message " << m << " crc " << crc;
      EXPECT_EQ(other.message, zero.message);
      EXPECT_EQ(other.counter, zero.counter);
      EXPECT_EQ(other.rate, zero.rate);
      EXPECT_EQ(other.accel, zero.accel);
      EXPECT_EQ(other.status_ok, zero.status_ok);
    }
  }
}

TEST(Mm710, RoundTripIsWithinHalfABit) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> rate(-2.8, 2.8), accel(-40, 40);
  for (int i = 0; i < 1000; ++i) {
    const ImuSample in =
        sample_of(rate(rng), rate(rng), rate(rng), accel(rng), accel(rng), accel(rng));
    mm710::Frame f[3];
    ASSERT_TRUE(mm710::encode(in, static_cast<std::uint8_t>(i), f));
    mm710::Assembler a;
    ImuSample out;
    mm710::Part p;
    for (int m = 0; m < 3; ++m) {
      ASSERT_TRUE(mm710::decode(f[m], p));
      EXPECT_EQ(p.message, m);
      EXPECT_EQ(p.counter, i & 0x0f);
      EXPECT_EQ(a.add(p, 42, out), m == 2);
    }
    EXPECT_EQ(out.t_ns, 42);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(out.gyro[k], in.gyro[k], kRateBit / 2 + 1e-12);
      EXPECT_NEAR(out.accel[k], in.accel[k], kAccelBit / 2 + 1e-12);
    }
  }
}

TEST(Mm710, ValuesBeyondTheRangeAreClampedAndReported) {
  mm710::Frame f[3];
  EXPECT_FALSE(mm710::encode(sample_of(0, 0, 4.0, 0, 0, 0), 0, f));  // 229 deg/s > 163.8
  EXPECT_EQ(f[0].data[0], 0xff);
  EXPECT_EQ(f[0].data[1], 0xff);
  mm710::Frame bad = f[0];
  bad.len = 6;
  mm710::Part p;
  EXPECT_FALSE(mm710::decode(bad, p));
  bad = f[0];
  bad.id = 0x175;
  EXPECT_FALSE(mm710::decode(bad, p));
}

// Feeds the frames of samples with the given counters, skipping listed (sample, message) pairs.
struct Feed {
  mm710::Assembler a;
  int delivered = 0;
  void sample(std::uint8_t counter, int skip_message = -1, bool flag = false) {
    mm710::Frame f[3];
    mm710::encode(sample_of(0.1, 0.2, 0.3, 1, 2, 3), counter, f);
    if (flag) f[1].data[2] |= 0x10;  // roll rate status: the sensor distrusts it
    for (int m = 0; m < 3; ++m) {
      if (m == skip_message) continue;
      mm710::Part p;
      mm710::decode(f[m], p);
      ImuSample s;
      if (a.add(p, 0, s)) ++delivered;
    }
  }
};

TEST(Mm710, LostFramesAreCountedPerMessageAndTheirSamplesDropped) {
  Feed feed;
  for (std::uint8_t c = 0; c < 4; ++c) feed.sample(c);
  feed.sample(4, 1);                                            // TX2 of sample 4 lost
  feed.sample(5, 0);                                            // TX1 of sample 5 lost
  feed.sample(6, 2);                                            // TX3 of sample 6 lost
  for (std::uint8_t c = 7; c < 40; ++c) feed.sample(c & 0x0f);  // counters wrap at 16
  EXPECT_EQ(feed.delivered, 4 + 33);
  const auto& n = feed.a.counters();
  EXPECT_EQ(n.lost_frames[0], 1u);
  EXPECT_EQ(n.lost_frames[1], 1u);
  EXPECT_EQ(n.lost_frames[2], 1u);
  EXPECT_EQ(n.incomplete_samples, 3u);
}

// A receiver that starts listening after a sample's first frame went by (the sensor was already
// sending) has lost nothing: the rest of that sample is skipped, the next one delivered.
TEST(Mm710, AStreamJoinedInsideASampleLosesNothing) {
  for (int joined_at = 1; joined_at < 3; ++joined_at) {
    Feed feed;
    mm710::Frame f[3];
    mm710::encode(sample_of(0.1, 0.2, 0.3, 1, 2, 3), 7, f);
    for (int m = joined_at; m < 3; ++m) {
      mm710::Part p;
      mm710::decode(f[m], p);
      ImuSample s;
      EXPECT_FALSE(feed.a.add(p, 0, s));
    }
    for (std::uint8_t c = 8; c < 12; ++c) feed.sample(c);
    feed.sample(12, 1);  // a real loss after that is still counted (by the next TX2's counter)
    feed.sample(13);
    EXPECT_EQ(feed.delivered, 5);
    EXPECT_EQ(feed.a.counters().incomplete_samples, 1u) << "joined at TX" << joined_at + 1;
    EXPECT_EQ(feed.a.counters().lost_frames[1], 1u);
    EXPECT_EQ(feed.a.counters().lost_frames[0], 0u);
  }
}

// The kernel registers a raw socket's three filters one after another: a receiver that binds while
// the sensor sends may get a sample's TX1 (or TX1 and TX2) and none of the rest. That is joining,
// not a loss; a frame missing after the first whole sample still is.
TEST(Mm710, AStreamJoinedWhileTheFiltersRegisterLosesNothing) {
  for (int first_missing = 1; first_missing < 3; ++first_missing) {
    Feed feed;
    mm710::Frame f[3];
    mm710::encode(sample_of(0.1, 0.2, 0.3, 1, 2, 3), 7, f);
    for (int m = 0; m < first_missing; ++m) {
      mm710::Part p;
      mm710::decode(f[m], p);
      ImuSample s;
      EXPECT_FALSE(feed.a.add(p, 0, s));
    }
    for (std::uint8_t c = 8; c < 12; ++c) feed.sample(c);
    EXPECT_EQ(feed.delivered, 4);
    EXPECT_EQ(feed.a.counters().incomplete_samples, 0u) << "first missing TX" << first_missing + 1;
    for (int m = 0; m < 3; ++m) EXPECT_EQ(feed.a.counters().lost_frames[m], 0u);
    feed.sample(12, 2);
    feed.sample(13);
    EXPECT_EQ(feed.delivered, 5);
    EXPECT_EQ(feed.a.counters().incomplete_samples, 1u);
    EXPECT_EQ(feed.a.counters().lost_frames[2], 1u);
  }
}

TEST(Mm710, AWholeLostSampleShowsInEveryMessagesCounter) {
  Feed feed;
  feed.sample(0);
  feed.sample(3);  // samples 1 and 2 never came
  EXPECT_EQ(feed.delivered, 2);
  for (int m = 0; m < 3; ++m) EXPECT_EQ(feed.a.counters().lost_frames[m], 2u);
  EXPECT_EQ(feed.a.counters().incomplete_samples, 0u);
}

TEST(Mm710, SamplesTheSensorFlagsAreDropped) {
  Feed feed;
  feed.sample(0);
  feed.sample(1, -1, true);
  feed.sample(2);
  EXPECT_EQ(feed.delivered, 2);
  EXPECT_EQ(feed.a.counters().flagged_samples, 1u);
}

// A socket pair carrying can_frame records, as a CAN_RAW socket delivers them.
struct Pair {
  int tx = -1, rx = -1;
  Pair() {
    int fds[2];
    if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds) == 0) {
      tx = fds[0];
      rx = fds[1];
    }
  }
  ~Pair() {
    if (tx >= 0) close(tx);
  }
  void raw(canid_t id, std::uint8_t len, std::uint8_t first = 0) {
    can_frame f{};
    f.can_id = id;
    f.len = len;
    f.data[0] = first;
    ASSERT_EQ(write(tx, &f, sizeof(f)), static_cast<ssize_t>(sizeof(f)));
  }
};

TEST(CanImu, DeliversSamplesAndSurvivesGarbageAndBusOff) {
  Pair pair;
  ASSERT_GE(pair.rx, 0);
  CanImu imu(pair.rx, "pair", 200'000'000);
  CanImuSender sender(pair.tx);
  const ImuSample in = sample_of(0.5, -0.25, 1.0, 0.1, -9.8, 0.3);
  ImuSample out;

  const std::int64_t before = monotonic_ns();
  ASSERT_TRUE(sender.send(in));
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);
  EXPECT_GE(out.t_ns, before);
  EXPECT_LE(out.t_ns, monotonic_ns());
  EXPECT_NEAR(out.gyro.x(), 0.5, kRateBit);

  pair.raw(mm710::kTx1, 3);                 // too short
  pair.raw(mm710::kTx2 | CAN_RTR_FLAG, 0);  // remote frame
  pair.raw(mm710::kTx3 | CAN_EFF_FLAG, 8);  // extended id with the same low bits
  pair.raw(0x123, 8);                       // someone else's message
  pair.raw(CAN_ERR_FLAG | CAN_ERR_BUSOFF, CAN_ERR_DLC);
  ASSERT_TRUE(sender.send(in));
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);
  const CanImuCounters& n = imu.counters();
  EXPECT_EQ(n.rejected_frames, 4u);
  EXPECT_EQ(n.error_frames, 1u);
  EXPECT_EQ(n.bus_off, 1u);
  EXPECT_EQ(n.recoveries, 1u) << "frames flowing again end the bus-off";
  EXPECT_FALSE(imu.bus_off());
  EXPECT_STREQ(imu.last_bus_error(), "bus-off");
  EXPECT_EQ(n.samples, 2u);
  EXPECT_EQ(n.lost_frames(), 0u);

  pair.raw(CAN_ERR_FLAG | CAN_ERR_BUSOFF, CAN_ERR_DLC);
  EXPECT_EQ(imu.next(out), hal::SourceStatus::kError);
  EXPECT_NE(std::string(imu.error()).find("bus-off"), std::string::npos) << imu.error();
  EXPECT_NE(std::string(imu.error()).find("restart-ms"), std::string::npos) << imu.error();
}

// On a fake time base: the frames are in the socket when the read starts, and the fake says they
// took kDelay to come. No sleep, no thread: nothing here depends on the machine's scheduling.
TEST(CanImu, TheWaitForFramesIsReportedApartFromTheRead) {
  Pair pair;
  ASSERT_GE(pair.rx, 0);
  test::FakeTimebase time;
  CanImu imu(pair.rx, "pair", 2'000'000'000, &time);
  CanImuSender sender(pair.tx);
  const ImuSample in = sample_of(0.5, -0.25, 1.0, 0.1, -9.8, 0.3);
  ImuSample out;
  // The sample's frames come 100 ms after the read starts: that time is the wait, not the read.
  constexpr std::int64_t kDelay = 100'000'000;
  ASSERT_TRUE(sender.send(in));
  time.data_after_ns = kDelay;
  const std::int64_t t0 = time.now_ns();
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);
  // All of the time next() took was the wait (decoding takes none of the fake time).
  EXPECT_EQ(imu.wait_ns(), kDelay);
  EXPECT_EQ(time.now_ns() - t0, kDelay);
  // Frames there already: no wait at all.
  ASSERT_TRUE(sender.send(in));
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);
  EXPECT_EQ(imu.wait_ns(), 0);
  EXPECT_EQ(time.now_ns() - t0, kDelay);
}

TEST(CanImu, ASilentBusIsReportedAsNotAnswering) {
  Pair pair;
  test::FakeTimebase time;
  CanImu imu(pair.rx, "pair", 50'000'000, &time);
  ImuSample out;
  const std::int64_t t0 = time.now_ns();
  EXPECT_EQ(imu.next(out), hal::SourceStatus::kError);
  EXPECT_EQ(time.now_ns() - t0, 50'000'000);
  EXPECT_EQ(imu.wait_ns(), 50'000'000);
  EXPECT_NE(std::string(imu.error()).find("stops answering"), std::string::npos) << imu.error();
}

// A sensor that stops mid-stream, or keeps the bus busy with frames that never make a sample
// (wrong length, or only TX1 over and over): both are a sensor that stopped answering.
TEST(CanImu, FramesThatNeverMakeASampleAreASensorThatStoppedAnswering) {
  Pair pair;
  test::FakeTimebase time;
  CanImu imu(pair.rx, "pair", 100'000'000, &time);
  CanImuSender sender(pair.tx);
  ImuSample out;
  ASSERT_TRUE(sender.send(sample_of(0.1, 0.2, 0.3, 0, 0, 9.8)));
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);
  // The bus kept busy with frames that never make a sample: TX1 alone, TX2 too short.
  constexpr int kJunk = 40;
  for (int k = 0; k < kJunk; ++k) {
    can_frame f{};
    f.can_id = k % 2 == 0 ? mm710::kTx1 : mm710::kTx2;
    f.len = static_cast<std::uint8_t>(k % 2 == 0 ? 8 : 5);
    f.data[6] = static_cast<std::uint8_t>(k & 0x0f);
    ASSERT_EQ(write(pair.tx, &f, sizeof(f)), static_cast<ssize_t>(sizeof(f)));
  }
  const std::int64_t t0 = time.now_ns();
  EXPECT_EQ(imu.next(out), hal::SourceStatus::kError);
  // The junk is read as it comes; then the bus is silent until the deadline.
  EXPECT_EQ(time.now_ns() - t0, 100'000'000);
  const std::string message = imu.error();
  EXPECT_EQ(message.rfind("pair: stops answering: ", 0), 0u) << message;
  EXPECT_NE(message.find(" frames in 100 ms but no complete MM7.10 sample"), std::string::npos)
      << message;
  EXPECT_GT(imu.counters().rejected_frames, 10u);
  EXPECT_GT(imu.counters().assembly.incomplete_samples, 10u);
  EXPECT_EQ(imu.counters().samples, 1u);
}

TEST(CanImu, OpeningAMissingInterfaceSaysSo) {
  try {
    open_mm710_socket("nosuchcan7");
    ADD_FAILURE() << "opened";
  } catch (const DriverError& e) {
    // Without CAN in the host's kernel the socket itself is missing; either way: kMissing.
    EXPECT_EQ(e.fault(), Fault::kMissing) << e.what();
    EXPECT_NE(std::string(e.what()).find("nosuchcan7"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace mirrorcal::drivers
