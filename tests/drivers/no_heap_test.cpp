// No heap on the drivers' read paths once streaming: the CAN IMU (frames, garbage, error frames
// on a socket pair) and the register IMUs (over the I2C and SPI register framing, against fakes)
// must not allocate per sample, nor when they report a failure.
#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <memory>

#include "alloc_counter.hpp"
#include "fakes.hpp"
#include "mirrorcal/drivers/can_imu.hpp"
#include "mirrorcal/drivers/register_imu.hpp"

namespace mirrorcal::drivers {
namespace {

using mirrorcal::test::AllocCounter;
using mirrorcal::test::AllocCounts;

TEST(DriversNoHeap, CounterSeesAllocations) {
  ASSERT_TRUE(mirrorcal::test::alloc_counter_installed());
  AllocCounter counter;
  int* a = new int(3);
  mirrorcal::test::escape(a);
  delete a;
  void* b = std::malloc(64);
  mirrorcal::test::escape(b);
  std::free(b);
  const AllocCounts c = counter.stop();
  EXPECT_GE(c.news, 1);
  EXPECT_GE(c.mallocs, 1);
}

TEST(DriversNoHeap, CanImuReadPath) {
  int fds[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds), 0);
  CanImu imu(fds[1], "pair", 100'000'000);
  CanImuSender sender(fds[0]);
  ImuSample in, out;
  in.gyro = Eigen::Vector3d(0.1, -0.2, 0.3);
  in.accel = Eigen::Vector3d(0.0, -9.8, 1.0);
  can_frame garbage{};
  garbage.can_id = mm710::kTx1;
  garbage.len = 2;
  can_frame bus_off{};
  bus_off.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
  bus_off.len = CAN_ERR_DLC;
  ASSERT_TRUE(sender.send(in));
  ASSERT_EQ(imu.next(out), hal::SourceStatus::kOk);  // warm-up outside the count

  AllocCounter counter;
  int ok = 0;
  for (int i = 0; i < 300; ++i) {
    if (i % 50 == 7) (void)!write(fds[0], &garbage, sizeof(garbage));
    if (i % 100 == 9) (void)!write(fds[0], &bus_off, sizeof(bus_off));
    sender.send(in);
    ok += imu.next(out) == hal::SourceStatus::kOk;
  }
  close(fds[0]);
  const hal::SourceStatus end = imu.next(out);  // the peer is gone: an error, reported in words
  const AllocCounts c = counter.stop();
  EXPECT_EQ(ok, 300);
  EXPECT_EQ(end, hal::SourceStatus::kError);
  EXPECT_EQ(imu.counters().rejected_frames, 6u);
  EXPECT_EQ(imu.counters().bus_off, 3u);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(DriversNoHeap, RegisterImuReadPaths) {
  RegisterImuConfig config;
  config.pace = false;
  config.timebase = &test::test_time();
  auto i2c = std::make_unique<test::FakeMpu6050>();
  test::FakeMpu6050& mpu_part = *i2c;
  Mpu6050 mpu(std::move(i2c), config);
  auto spi = std::make_unique<test::FakeIcm42688>();
  test::FakeIcm42688& icm_part = *spi;
  Icm42688 icm(std::make_unique<SpiRegisterBus>(std::move(spi)), config);
  icm_part.first_bytes.reserve(2000);  // the fake's own log must not count

  AllocCounter counter;
  ImuSample s;
  int ok = 0;
  for (int i = 0; i < 500; ++i) {  // past the once-a-second WHO_AM_I checks
    ok += mpu.next(s) == hal::SourceStatus::kOk;
    ok += icm.next(s) == hal::SourceStatus::kOk;
  }
  mpu_part.dead = true;
  const hal::SourceStatus end = mpu.next(s);
  const AllocCounts c = counter.stop();
  EXPECT_EQ(ok, 1000);
  EXPECT_EQ(end, hal::SourceStatus::kError);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

}  // namespace
}  // namespace mirrorcal::drivers
