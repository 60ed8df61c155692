// The writer the board's loop will record through allocates nothing per sample or frame once
// open (allocations counted by tests/support/alloc_counter).
#include <gtest/gtest.h>

#include <algorithm>

#include "alloc_counter.hpp"
#include "test_support.hpp"

using namespace rectest;

TEST(RecordingWriter, TheCounterSeesAllocations) {
  ASSERT_TRUE(mc::test::alloc_counter_installed());
  mc::test::AllocCounter counting;
  auto* v = new std::vector<double>(1000);
  mc::test::escape(v);
  const auto c = counting.stop();
  delete v;
  EXPECT_GE(c.total(), 1);
}

TEST(RecordingWriter, AddsSamplesFramesAndImagesWithoutTheHeap) {
  const TempDir tmp("writer-no-heap");
  std::string err;
  mc::sim::RecordingWriter w;
  ASSERT_TRUE(w.open(tmp.path, err)) << err;
  const std::uint8_t pixels[4 * 3] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  const mc::sim::GrayImage image{4, 3, pixels};
  mc::MarkerFrame<3> frame;
  frame.seen = {true, true, false};
  frame.uv.fill(Eigen::Vector2d::Zero());
  // The first image creates cam0/data/ (it may allocate, once): before arming.
  frame.t_ns = 1;
  ASSERT_TRUE(w.add_frame(frame, &image));

  mc::test::AllocCounter counting;
  bool ok = true;
  for (int k = 0; k < 2000; ++k) {  // enough rows to flush the stdio buffers several times
    mc::ImuSample s;
    s.t_ns = 10 + 5 * k;
    s.gyro = Eigen::Vector3d(0.1 * k, -2e-7, 3.0);
    s.accel = Eigen::Vector3d(9.81, 1.0 / (k + 1), -0.5);
    ok = w.add_imu(s) && ok;
    if (k % 10 == 0) {
      frame.t_ns = 12 + 5 * k;
      frame.uv[0] = Eigen::Vector2d(320.123456789 + k, 240.5);
      frame.uv[1] = Eigen::Vector2d(1e-9, 479.99999999);
      ok = w.add_frame(frame, k % 100 == 0 ? &image : nullptr) && ok;
    }
  }
  const auto c = counting.stop();
  EXPECT_TRUE(ok) << w.error();
  EXPECT_EQ(c.total(), 0);
  ASSERT_TRUE(w.close(err)) << err;
  // It did write: 2000 samples and a header.
  const std::string imu = slurp(tmp.path + "/mav0/imu0/data.csv");
  EXPECT_EQ(std::count(imu.begin(), imu.end(), '\n'), 2001);
  EXPECT_TRUE(fs::exists(tmp.path + "/mav0/cam0/data/512.pgm"));
}
