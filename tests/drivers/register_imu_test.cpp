// The register IMUs against fakes of the parts: identification, configuration as the data sheets
// ask, conversion with their scales, data-ready pacing and the failures a user meets.
#include <gtest/gtest.h>

#include <cerrno>
#include <cmath>
#include <cstring>

#include "fakes.hpp"
#include "mirrorcal/drivers/monotonic_clock.hpp"
#include "mirrorcal/drivers/register_imu.hpp"

namespace mirrorcal::drivers {
namespace {

using test::FakeDataReady;
using test::FakeIcm42688;
using test::FakeMpu6050;
using test::kG;
using test::kPi;

RegisterImuConfig unpaced(double rate_hz = 200, double gyro_dps = 500, double accel_g = 4) {
  RegisterImuConfig c;
  c.rate_hz = rate_hz;
  c.gyro_range_dps = gyro_dps;
  c.accel_range_g = accel_g;
  c.pace = false;
  c.timebase = &test::test_time();
  return c;
}

// Paced by the part's data-ready status, as without a data-ready line on the board.
RegisterImuConfig paced(double rate_hz) {
  RegisterImuConfig c = unpaced(rate_hz);
  c.pace = true;
  return c;
}

template <class Fn>
DriverError expect_throw(Fn fn) {
  try {
    fn();
  } catch (const DriverError& e) {
    return e;
  }
  ADD_FAILURE() << "no DriverError";
  return DriverError(Fault::kIo, "");
}

TEST(Mpu6050, ConfiguresAndConvertsWithTheDataSheetScales) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeMpu6050& part = *bus;
  Mpu6050 imu(std::move(bus), unpaced(200, 400, 3));
  // 400 deg/s needs +-500 (FS_SEL 1), 3 g needs +-4 g (AFS_SEL 1); 1 kHz / (1 + 4) = 200 Hz.
  EXPECT_EQ(part.regs_[0x1B], 1 << 3);
  EXPECT_EQ(part.regs_[0x1C], 1 << 3);
  EXPECT_EQ(part.regs_[0x19], 4);
  EXPECT_EQ(part.regs_[0x6B] & 0x40, 0) << "left asleep";
  EXPECT_EQ(part.regs_[0x38] & 1, 1) << "data-ready interrupt off";
  EXPECT_EQ(imu.period_ns(), 5'000'000);

  const double gyro[3] = {123.4, -56.7, 0.25}, accel[3] = {0.5, -1.25, 2.9};
  for (int i = 0; i < 3; ++i) {
    part.gyro_dps[i] = gyro[i];
    part.accel_g[i] = accel[i];
  }
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  for (int i = 0; i < 3; ++i) {
    // Within half a count of the data sheet's sensitivity (65.5 LSB/(deg/s), 8192 LSB/g).
    EXPECT_NEAR(s.gyro[i], gyro[i] * kPi / 180, 0.5 / 65.5 * kPi / 180 + 1e-12);
    EXPECT_NEAR(s.accel[i], accel[i] * kG, 0.5 / 8192 * kG + 1e-12);
  }
  EXPECT_LE(part.largest_read, 32u) << "an SMBus block read carries at most 32 bytes";
}

TEST(Mpu6050, RefusesOtherPartsAndSilentBuses) {
  auto other = std::make_unique<FakeMpu6050>();
  other->regs_[0x75] = 0x71;  // an MPU-9250
  const DriverError wrong = expect_throw([&] { Mpu6050 imu(std::move(other), unpaced()); });
  EXPECT_EQ(wrong.fault(), Fault::kWrongKind);
  EXPECT_NE(std::string(wrong.what()).find("0x71"), std::string::npos) << wrong.what();

  auto dead = std::make_unique<FakeMpu6050>();
  dead->dead = true;
  const DriverError silent = expect_throw([&] { Mpu6050 imu(std::move(dead), unpaced()); });
  EXPECT_EQ(silent.fault(), Fault::kNotAnswering) << silent.what();
  EXPECT_NE(std::string(silent.what()).find("fake-mpu6050"), std::string::npos);

  auto fine = std::make_unique<FakeMpu6050>();
  EXPECT_EQ(expect_throw([&] { Mpu6050 imu(std::move(fine), unpaced(200, 2500)); }).fault(),
            Fault::kBadSpec);
}

// i2c-dev's answers when the part goes away mid-run: no acknowledge (EREMOTEIO from most
// adapters, ENXIO from some), a stretched clock (ETIMEDOUT), a bus in error (EIO).
TEST(Mpu6050, ReportsAPartThatStopsAnswering) {
  for (const int err : {EREMOTEIO, ENXIO, ETIMEDOUT, EIO}) {
    auto bus = std::make_unique<FakeMpu6050>();
    FakeMpu6050& part = *bus;
    Mpu6050 imu(std::move(bus), unpaced());
    ImuSample s;
    ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
    part.dead = true;
    part.dead_errno = err;
    EXPECT_EQ(imu.next(s), hal::SourceStatus::kError);
    const std::string message = imu.error();
    EXPECT_NE(message.find("fake-mpu6050: stops answering"), std::string::npos) << message;
    EXPECT_NE(message.find(std::strerror(err)), std::string::npos) << message;
  }
}

// A part that reset (a brown-out) wakes asleep with its data registers cleared: all zeros.
TEST(Mpu6050, APartThatResetIsNotTakenForASample) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeMpu6050& part = *bus;
  Mpu6050 imu(std::move(bus), unpaced());
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  part.regs_[0x6B] = 0x40;  // PWR_MGMT_1 back to its reset value: asleep
  EXPECT_EQ(imu.next(s), hal::SourceStatus::kError);
  EXPECT_NE(std::string(imu.error()).find("0x00 throughout"), std::string::npos) << imu.error();
}

TEST(Mpu6050, DataReadyEdgesTimeTheSamplesAndRevealMissedOnes) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeDataReady drdy;
  Mpu6050 imu(std::move(bus), unpaced(), &drdy);
  const std::int64_t p = 5'000'000;
  // Edges at 0, 1, 2, then 5 periods (3 and 4 were never seen), then 6.
  for (const std::int64_t k : {0, 1, 2, 5, 6}) drdy.edges.push_back(1'000'000'000 + k * p);
  std::int64_t expected[] = {0, 1, 2, 5, 6};
  for (const std::int64_t k : expected) {
    ImuSample s;
    ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
    EXPECT_EQ(s.t_ns, 1'000'000'000 + k * p);
  }
  EXPECT_EQ(imu.counters().missed_samples, 2u);
  EXPECT_EQ(imu.counters().samples, 5u);
  ImuSample s;
  EXPECT_EQ(imu.next(s), hal::SourceStatus::kError);  // no more edges: the part went quiet
  EXPECT_NE(std::string(imu.error()).find("no data-ready edge"), std::string::npos) << imu.error();
  // 20 periods, at least 200 ms.
  EXPECT_EQ(drdy.last_timeout_ns, 200'000'000);
}

TEST(Mpu6050, ADataReadyLineThatFailsIsNamedWithTheImu) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeDataReady drdy;
  Mpu6050 imu(std::move(bus), unpaced(), &drdy);
  drdy.edges.push_back(1'000'000'000);
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  drdy.broken = true;
  EXPECT_EQ(imu.next(s), hal::SourceStatus::kError);
  EXPECT_EQ(std::string(imu.error()),
            "fake-mpu6050: data-ready line failed: gpiochip0:17: read failed: ENODEV");
}

TEST(Mpu6050, TheWaitForTheDataReadyEdgeIsReportedApartFromTheRead) {
  FakeDataReady drdy;
  Mpu6050 imu(std::make_unique<FakeMpu6050>(), unpaced(), &drdy);
  drdy.edges = {1'000'000'000, 1'005'000'000};
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  EXPECT_LT(imu.wait_ns(), 50'000'000) << "the edge was there at once";
  drdy.delay_ns = 50'000'000;  // the next edge is 50 ms away
  const std::int64_t t0 = test::test_time().now_ns();
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  const std::int64_t elapsed = test::test_time().now_ns() - t0;
  EXPECT_GE(imu.wait_ns(), drdy.delay_ns);
  EXPECT_LE(imu.wait_ns(), elapsed);
}

TEST(Icm42688, ConfiguresOverSpiAndConvertsWithTheDataSheetScales) {
  auto transport = std::make_unique<FakeIcm42688>();
  FakeIcm42688& part = *transport;
  part.bank = 2;  // left in another register bank by someone
  Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(transport)), unpaced(1000, 250, 2));
  EXPECT_EQ(part.resets, 2u) << "one soft reset (plus the fake's power-on)";
  EXPECT_EQ(part.bank0[0x4E], 0x0F) << "gyro and accelerometer in low-noise mode";
  EXPECT_EQ(part.bank0[0x4F], (3 << 5) | 6) << "+-250 deg/s at 1 kHz";
  EXPECT_EQ(part.bank0[0x50], (3 << 5) | 6) << "+-2 g at 1 kHz";
  EXPECT_EQ(part.bank0[0x65] & 0x08, 0x08) << "data ready on INT1";
  EXPECT_EQ(imu.period_ns(), 1'000'000);
  // SPI framing: every transfer starts with a register address, bit 7 set for reads only.
  for (const std::uint8_t b : part.first_bytes) EXPECT_TRUE((b & 0x7f) <= 0x76);

  const double gyro[3] = {-200.0, 17.125, 249.0}, accel[3] = {1.999, -0.001, -1.5};
  for (int i = 0; i < 3; ++i) {
    part.gyro_dps[i] = gyro[i];
    part.accel_g[i] = accel[i];
  }
  ImuSample s;
  const std::size_t before = part.transfers;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  EXPECT_EQ(part.transfers, before + 1) << "one burst read per sample";
  EXPECT_EQ(part.first_bytes.back(), 0x80 | 0x1F);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(s.gyro[i], gyro[i] * kPi / 180, 0.5 / 131 * kPi / 180 + 1e-12);
    EXPECT_NEAR(s.accel[i], accel[i] * kG, 0.5 / 16384 * kG + 1e-12);
  }
}

TEST(Icm42688, SensorsLeftOffWouldShowAsFullScaleNegative) {
  // The fake's own check: data read with PWR_MGMT0 off is -32768, which the test above rules out.
  FakeIcm42688 part;
  const std::uint8_t tx[3] = {0x80 | 0x1F, 0, 0};
  std::uint8_t rx[3];
  part.transfer(tx, rx, 3);
  EXPECT_EQ(rx[1], 0x80);
  EXPECT_EQ(rx[2], 0x00);
}

TEST(Icm42688, RefusesUnsupportedRatesAndAnUnpluggedPart) {
  auto t1 = std::make_unique<FakeIcm42688>();
  const DriverError rate = expect_throw(
      [&] { Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(t1)), unpaced(300)); });
  EXPECT_EQ(rate.fault(), Fault::kBadSpec);
  EXPECT_NE(std::string(rate.what()).find("200, 500"), std::string::npos) << rate.what();

  auto t2 = std::make_unique<FakeIcm42688>();
  t2->unplugged = true;
  const DriverError gone = expect_throw(
      [&] { Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(t2)), unpaced()); });
  EXPECT_EQ(gone.fault(), Fault::kNotAnswering);
  EXPECT_NE(std::string(gone.what()).find("0xff"), std::string::npos) << gone.what();
}

// A part that stops answering mid-run, in each way an SPI bus shows it: no sample of it may reach
// the filter, and the message names the device and what it read.
TEST(Icm42688, APartThatStopsAnsweringEndsTheStreamAtOnce) {
  struct Case {
    const char* what;
    void (*stop)(FakeIcm42688&);
    const char* expected;
  };
  const Case cases[] = {
      {"unplugged (MISO floats high)", [](FakeIcm42688& p) { p.unplugged = true; }, "0xff"},
      {"MISO held low", [](FakeIcm42688& p) { p.miso_low = true; }, "0x00"},
      {"reset by a brown-out (sensors off, WHO_AM_I still right)",
       [](FakeIcm42688& p) {
         const std::uint8_t soft_reset[2] = {0x11, 0x01};  // DEVICE_CONFIG, as the SPI bus writes
         std::uint8_t rx[2];
         p.transfer(soft_reset, rx, 2);
       },
       "sensors are off"},
  };
  for (const Case& c : cases) {
    auto transport = std::make_unique<FakeIcm42688>();
    FakeIcm42688& part = *transport;
    Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(transport)), unpaced(200));
    ImuSample s;
    ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk) << c.what;
    c.stop(part);
    EXPECT_EQ(imu.next(s), hal::SourceStatus::kError) << c.what;
    const std::string message = imu.error();
    EXPECT_NE(message.find("fake-icm42688: stops answering"), std::string::npos) << message;
    EXPECT_NE(message.find(c.expected), std::string::npos) << c.what << ": " << message;
    EXPECT_EQ(imu.counters().samples, 1u) << c.what;
  }
}

// Within a second, a part that still answers but is no longer the one configured (WHO_AM_I).
TEST(Icm42688, NoticesWithinASecondWhenThePartIsReplaced) {
  auto transport = std::make_unique<FakeIcm42688>();
  FakeIcm42688& part = *transport;
  Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(transport)), unpaced(200));
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  part.bank0[0x75] = 0x6f;  // an ICM-20689 answers now
  int delivered = 0;
  while (imu.next(s) == hal::SourceStatus::kOk && delivered < 1000) ++delivered;
  EXPECT_LT(delivered, 200) << "a second of samples at 200 Hz";
  EXPECT_NE(std::string(imu.error()).find("WHO_AM_I reads 0x6f"), std::string::npos) << imu.error();
}

// Without a data-ready line the part's data-ready status paces the reads: whether its oscillator
// runs 3 % slow or fast against the host's clock, every sample is read once, in order, at the
// part's own rate (a host pacing by its clock alone would read some twice or skip some).
TEST(Mpu6050, PacedWithoutDataReadyReadsEachSampleOnceWhateverThePartsClock) {
  // 50 Hz: periods long against a loaded machine's scheduling delays.
  constexpr double kRate = 50;
  constexpr int kSamples = 40;
  for (const double clock_scale : {0.97, 1.03}) {
    auto bus = std::make_unique<FakeMpu6050>();
    FakeMpu6050& part = *bus;
    part.clock_scale = clock_scale;
    Mpu6050 imu(std::move(bus), paced(kRate));
    std::int64_t last = -1, first_t = 0;
    ImuSample s;
    for (int i = 0; i < kSamples; ++i) {
      ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk) << imu.error();
      if (i == 0) first_t = s.t_ns;
      EXPECT_EQ(part.last_data_sample, last < 0 ? part.last_data_sample : last + 1)
          << "clock " << clock_scale << ", sample " << i;
      last = part.last_data_sample;
    }
    // The samples came at the part's rate, not the board's nominal one: 3 % is 23 ms here.
    const double seconds = static_cast<double>(s.t_ns - first_t) * 1e-9;
    EXPECT_NEAR(seconds, (kSamples - 1) / kRate / clock_scale, 0.5 / kRate) << clock_scale;
    EXPECT_EQ(imu.counters().missed_samples, 0u);
  }
}

TEST(Mpu6050, PacedWithoutDataReadyCountsTheSamplesALateLoopMissed) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeMpu6050& part = *bus;
  Mpu6050 imu(std::move(bus), paced(50));
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  const std::int64_t before = part.last_data_sample;
  test::test_time().advance(62'000'000);  // the loop is busy for 3.1 periods
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  const std::int64_t skipped = part.last_data_sample - before - 1;
  EXPECT_EQ(skipped, 2);
  EXPECT_EQ(imu.counters().missed_samples, static_cast<std::uint64_t>(skipped));
}

TEST(Mpu6050, PacedWithoutDataReadyAPartThatStopsSamplingIsNamed) {
  auto bus = std::make_unique<FakeMpu6050>();
  FakeMpu6050& part = *bus;
  Mpu6050 imu(std::move(bus), paced(200));
  ImuSample s;
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  part.frozen_sample = part.sample_number();  // no new sample: data-ready never set again
  std::int64_t t0 = test::test_time().now_ns();
  hal::SourceStatus st = imu.next(s);
  if (st == hal::SourceStatus::kOk) {  // the one that came since the last read
    t0 = test::test_time().now_ns();
    st = imu.next(s);
  }
  EXPECT_EQ(st, hal::SourceStatus::kError);
  EXPECT_GE(test::test_time().now_ns() - t0, 200'000'000);
  EXPECT_NE(
      std::string(imu.error()).find("fake-mpu6050: stops answering: no new sample for 200 ms"),
      std::string::npos)
      << imu.error();
}

TEST(Icm42688, PacedByTheClockWithoutDataReady) {
  auto transport = std::make_unique<FakeIcm42688>();
  Icm42688 imu(std::make_unique<SpiRegisterBus>(std::move(transport)), paced(1000));
  ImuSample first, s;
  // The samples are due at absolute times from the first call on (a late one is caught up, not
  // the schedule shifted), so measure from before that call: a loaded machine may wake the first
  // read late, but no sample comes before its time.
  const std::int64_t start = test::test_time().now_ns();
  ASSERT_EQ(imu.next(first), hal::SourceStatus::kOk);
  for (int i = 0; i < 20; ++i) ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  // 20 new samples of the part's 1 kHz: never faster than its rate (the first may have been in
  // its registers already, the 20th came at least 19 periods later).
  EXPECT_GE(s.t_ns - start, 19 * 1'000'000);
  // The poll for the part's status is the wait, and a read lasts no longer than its wait and more.
  const std::int64_t t0 = test::test_time().now_ns();
  ASSERT_EQ(imu.next(s), hal::SourceStatus::kOk);
  EXPECT_GT(imu.wait_ns(), 0);
  EXPECT_LE(imu.wait_ns(), test::test_time().now_ns() - t0);
}

}  // namespace
}  // namespace mirrorcal::drivers
