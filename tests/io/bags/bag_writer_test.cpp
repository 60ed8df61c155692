// io::BagWriter (record --bag's) against the bag reader, in the build that sanitizes them: a ROS 2
// bag of two seconds of the paper rig (its IMU at 200 Hz, its frames as images whose pixels all
// change from frame to frame) reads back sample for sample and pixel for pixel at the stamps
// written, through the calibration's own way in (open_bag_recording); a folder that cannot be
// written is named. The strict MCAP reader of tests/io/bags checks the file's records, indexes and
// CRCs (bags_calibrate_as_their_folder).
#include <gtest/gtest.h>

#include <cstdint>
#include <string>
#include <vector>

#include "mirrorcal/io/bags.hpp"
#include "recording_support.hpp"

using namespace rectest;

namespace {

// Frame j's pixel (x, y): every one changes from frame to frame.
std::uint8_t pixel(int x, int y, std::size_t j) {
  return static_cast<std::uint8_t>(x * 7 + y * 13 + static_cast<int>(j) * 29);
}

TEST(BagWriter, WritesWhatTheReaderReadsBack) {
  TempDir tmp("bag-writer");
  const std::string dir = tmp.path + "/bag";
  const auto s = short_scenario(2.0);
  const mc::sim::SimData data = mc::sim::simulate(s, 7);
  mc::io::SensorInfo sensors = sensors_of(s);
  sensors.width = 64;
  sensors.height = 48;
  sensors.imu_model = mc::ImuModel::kCalibrated;
  std::string err;
  {
    mc::io::BagWriter bag;
    ASSERT_TRUE(bag.open(dir, "bag", sensors.imu_rostopic, sensors.rostopic, err)) << err;
    std::vector<std::uint8_t> pixels(std::size_t(sensors.width * sensors.height));
    const mc::io::GrayImage image{sensors.width, sensors.height, pixels.data()};
    std::size_t i = 0;
    for (std::size_t j = 0; j < data.frames.size(); ++j) {
      for (; i < data.imu.size() && data.imu[i].t_ns <= data.frames[j].t_ns; ++i)
        ASSERT_TRUE(bag.add_imu(data.imu[i]));
      for (int y = 0; y < sensors.height; ++y)
        for (int x = 0; x < sensors.width; ++x)
          pixels[std::size_t(y * sensors.width + x)] = pixel(x, y, j);
      ASSERT_TRUE(bag.add_image(data.frames[j].t_ns, image));
    }
    for (; i < data.imu.size(); ++i) ASSERT_TRUE(bag.add_imu(data.imu[i]));
    ASSERT_TRUE(bag.close(err)) << err;
  }
  write_sensor_files(dir, s, sensors, data, 7);

  mc::io::Recording rec;
  ASSERT_TRUE(mc::io::open_bag_recording(dir, {}, mc::sim::kPaperMarkers, rec, err)) << err;
  const auto imu = rec.streams->open_imu();
  mc::ImuSample sample;
  std::size_t n = 0;
  while (imu->next(sample) == mc::hal::SourceStatus::kOk) {
    ASSERT_LT(n, data.imu.size());
    EXPECT_EQ(sample.t_ns, data.imu[n].t_ns) << "sample " << n;
    EXPECT_EQ(sample.gyro, data.imu[n].gyro) << "sample " << n;
    EXPECT_EQ(sample.accel, data.imu[n].accel) << "sample " << n;
    ++n;
  }
  EXPECT_EQ(n, data.imu.size());
  // The images of the frames within the IMU data, in order.
  const auto images = rec.streams->open_images();
  ASSERT_NE(images, nullptr);
  mc::hal::FrameView view;
  std::size_t j = 0, read = 0;
  while (images->poll(view) == mc::hal::SourceStatus::kOk) {
    while (j < data.frames.size() && data.frames[j].t_ns < view.t_ns) ++j;
    ASSERT_LT(j, data.frames.size()) << "an image at " << view.t_ns << " ns was never written";
    ASSERT_EQ(view.t_ns, data.frames[j].t_ns);
    ASSERT_EQ(view.width, sensors.width);
    ASSERT_EQ(view.height, sensors.height);
    int wrong = 0;
    for (int y = 0; y < view.height; ++y)
      for (int x = 0; x < view.width; ++x) wrong += view.luma(x, y) != pixel(x, y, j) ? 1 : 0;
    EXPECT_EQ(wrong, 0) << "frame " << j;
    ++read;
  }
  EXPECT_EQ(read, std::size_t(rec.stats.frames));
  EXPECT_GT(read, data.frames.size() - 2);  // all, but those outside the IMU's data
}

TEST(BagWriter, AFolderThatCannotBeWrittenIsNamed) {
  TempDir tmp("bag-writer-bad");
  const std::string file = tmp.path + "/a-file";
  spit(file, "not a folder\n");
  mc::io::BagWriter bag;
  std::string err;
  EXPECT_FALSE(bag.open(file + "/bag", "bag", "/imu0", "/cam0/image_raw", err));
  EXPECT_NE(err.find(file + "/bag/bag_0.mcap"), std::string::npos) << err;
}

}  // namespace
