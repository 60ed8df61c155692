// The writer the board's loop will record through allocates nothing per sample or frame once
// open (allocations counted by tests/support/alloc_counter).
#include <gtest/gtest.h>

#include <algorithm>

#include "alloc_counter.hpp"
#include "mirrorcal/calibration/recording_run.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "recording_support.hpp"

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
  mc::io::RecordingWriter w;
  ASSERT_TRUE(w.open(tmp.path, err)) << err;
  const std::uint8_t pixels[4 * 3] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  const mc::io::GrayImage image{4, 3, pixels};
  mc::MarkerFrame<3> frame;
  frame.seen = {true, true, false};
  frame.uv.fill(Eigen::Vector2d::Zero());
  // The first image creates cam0/data/ and the PNG writer (it may allocate, once): before arming.
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
  EXPECT_TRUE(fs::exists(tmp.path + "/mav0/cam0/data/512.png"));
}

// Calibrating from images reads one per frame: the reader and the PNG writer allocate their
// buffers when made, and neither reading nor writing an image touches the heap (zlib included).
TEST(ImageReader, ReadsAndWritesImagesWithoutTheHeap) {
  const TempDir tmp("reader-no-heap");
  std::vector<std::uint8_t> pixels(64 * 48);
  for (std::size_t k = 0; k < pixels.size(); ++k) pixels[k] = std::uint8_t((k * 37) ^ (k >> 5));
  mc::io::PngWriter writer(64, 48);
  mc::io::ImageReader reader(64, 48);
  const std::string png_path = tmp.path + "/1.png", pgm_path = tmp.path + "/2.pgm";
  std::size_t n = 0;
  const std::uint8_t* png = writer.encode({64, 48, pixels.data()}, n);
  ASSERT_NE(png, nullptr) << writer.error();
  spit(png_path, std::string(reinterpret_cast<const char*>(png), n));
  spit(pgm_path, "P5\n64 48\n255\n" + std::string(pixels.begin(), pixels.end()));

  mc::test::AllocCounter counting;
  bool ok = true, same = true;
  for (int k = 0; k < 50; ++k) {
    mc::io::GrayImage image;
    for (const std::string* path : {&png_path, &pgm_path}) {
      ok = reader.read(path->c_str(), image) && ok;
      same = same && image.width == 64 && image.height == 48 &&
             std::equal(pixels.begin(), pixels.end(), image.pixels);
    }
    ok = writer.encode({64, 48, pixels.data()}, n) != nullptr && ok;
  }
  const auto c = counting.stop();
  EXPECT_TRUE(ok) << reader.error() << writer.error();
  EXPECT_TRUE(same);
  EXPECT_EQ(c.total(), 0);
}

// Calibrating from images: a pass's marker source (each frame's image read from its file, its
// markers detected and labelled) allocates when opened and never per frame.
TEST(ImageReader, APassOverImagesDoesNotAllocatePerFrame) {
  const TempDir tmp("images-pass-no-heap");
  const mc::sim::Scenario s = short_scenario(1.0);
  const mc::sim::SimData data = mc::sim::simulate(s, 3);
  write_recording(tmp.path, s, data, 3);
  {  // the same recording with its images (over the one written above)
    std::string err;
    mc::io::RecordingWriter w;
    ASSERT_TRUE(w.open(tmp.path, err)) << err;
    for (const auto& smp : data.imu) w.add_imu(smp);
    const mc::sim::RenderConfig render;
    mc::sim::FrameRenderer renderer(s, render, 7);
    std::vector<std::uint8_t> pixels(std::size_t(renderer.width()) *
                                     std::size_t(renderer.height()));
    const mc::io::GrayImage image{renderer.width(), renderer.height(), pixels.data()};
    std::uint64_t j = 0;
    for (const auto& f : data.frames) {
      for (const auto& m : f.markers)
        renderer.add_spot(m.u, m.v, render.brightness[std::size_t(m.id)]);
      renderer.finish(j++, pixels.data());
      ASSERT_TRUE(w.add_frame(f, &image)) << w.error();
    }
    ASSERT_TRUE(w.close(err)) << err;
  }
  mc::io::Recording rec;
  std::string err;
  ASSERT_TRUE(mc::io::open_recording(tmp.path, mc::sim::kPaperMarkers, rec, err, true)) << err;
  const mc::calibration::LoopData loop_data = mc::calibration::recording_loop_data(rec);
  const auto source = loop_data.open_markers<mc::sim::kPaperMarkers>();
  auto* relabeler = dynamic_cast<mc::hal::MarkerRelabeler<mc::sim::kPaperMarkers>*>(source.get());
  ASSERT_NE(relabeler, nullptr);
  mc::MarkerFrame<mc::sim::kPaperMarkers> frame;
  ASSERT_EQ(source->poll(frame), mc::hal::SourceStatus::kOk);  // the first: start-up
  // The loop's prediction, here the pixels the spots were drawn at, 2 px sigma.
  std::vector<mc::hal::MarkerPrediction<mc::sim::kPaperMarkers>> predictions(data.frames.size());
  std::size_t listed = 0;
  for (std::size_t k = 0; k < data.frames.size(); ++k)
    for (const auto& m : data.frames[k].markers) {
      const auto i = std::size_t(m.id);
      predictions[k].valid[i] = true;
      predictions[k].uv[i] = Eigen::Vector2d(m.u, m.v);
      predictions[k].covariance[i] = 4.0 * Eigen::Matrix2d::Identity();
      listed += k > 0 ? 1 : 0;
    }

  mc::test::AllocCounter counting;
  std::size_t frames = 1, markers = 0;
  while (source->poll(frame) == mc::hal::SourceStatus::kOk) {
    if (frames < predictions.size()) relabeler->relabel(predictions[frames], frame);
    ++frames;
    for (const bool seen : frame.seen) markers += seen ? 1 : 0;
  }
  const auto c = counting.stop();
  EXPECT_EQ(c.total(), 0);
  EXPECT_EQ(frames, data.frames.size());
  // It did detect and label: nearly every marker drawn, none twice.
  EXPECT_GT(double(markers), 0.95 * double(listed));
  EXPECT_LE(markers, listed);
  EXPECT_STREQ(source->error(), "");
}
