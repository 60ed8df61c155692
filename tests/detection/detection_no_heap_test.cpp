// No heap per frame on the camera path: detection, identification and the filter's prediction
// for it, as the loop runs them, must not allocate (allocations counted by
// tests/support/alloc_counter).
#include <gtest/gtest.h>

#include <vector>

#include "alloc_counter.hpp"
#include "mirrorcal/detection/detecting_marker_source.hpp"
#include "mirrorcal/estimator/prior.hpp"
#include "mirrorcal/loop/marker_prediction.hpp"
#include "mirrorcal/sim/frame_renderer.hpp"
#include "mirrorcal/sim/simulator.hpp"

namespace mc = mirrorcal;

namespace {

constexpr int M = 3;

// Serves frames rendered beforehand, so that rendering's own allocations stay out of the count.
class PrerenderedFrames final : public mc::hal::FrameSource {
 public:
  PrerenderedFrames(const mc::sim::Scenario& s, const mc::sim::RenderConfig& rc, int count) {
    mc::sim::FrameRenderer r(s, rc, 5);
    mc::sim::RenderedTruth truth;
    for (int k = 0; k < count; ++k) {
      images_.emplace_back(static_cast<std::size_t>(r.bytes_per_line() * r.height()));
      times_.push_back(mc::sim::frame_time_ns(s, static_cast<std::uint64_t>(k)));
      r.render(times_.back(), static_cast<std::uint64_t>(k), images_.back().data(), truth);
    }
    view_.format = rc.format;
    view_.width = r.width();
    view_.height = r.height();
    view_.bytes_per_line = r.bytes_per_line();
  }
  mc::hal::SourceStatus poll(mc::hal::FrameView& frame) override {
    if (next_ >= images_.size()) return mc::hal::SourceStatus::kEndOfStream;
    frame = view_;
    frame.data = images_[next_].data();
    frame.bytes = images_[next_].size();
    frame.t_ns = times_[next_];
    frame.sequence = static_cast<std::uint32_t>(next_++);
    return mc::hal::SourceStatus::kOk;
  }

 private:
  std::vector<std::vector<std::uint8_t>> images_;
  std::vector<std::int64_t> times_;
  mc::hal::FrameView view_{};
  std::size_t next_ = 0;
};

}  // namespace

TEST(DetectionNoHeap, CounterWorks) {
  ASSERT_TRUE(mc::test::alloc_counter_installed());
  mc::test::AllocCounter armed;
  std::vector<int> v(10);
  asm volatile("" : : "g"(v.data()) : "memory");
  EXPECT_GE(armed.stop().news, 1);
}

TEST(DetectionNoHeap, PollPredictAndRelabelDoNotAllocate) {
  const mc::sim::Scenario s = mc::sim::paper_scenario();
  for (const auto format : {mc::hal::PixelFormat::kGrey, mc::hal::PixelFormat::kYuyv}) {
    mc::sim::RenderConfig rc;
    rc.format = format;
    PrerenderedFrames frames(s, rc, 40);
    mc::detection::DetectingMarkerSource<M> source(frames, {}, s.truth.width, s.truth.height);

    using Filter = mc::CalibrationFilter<double, M, 0>;
    mc::CalibrationConfig cfg;
    cfg.intrinsics = s.truth.intrinsics;
    cfg.gravity_n = s.gravity_n;
    Filter filter(cfg);
    const mc::sim::SimData data = mc::sim::simulate(s, 2);
    const auto prior = mc::sim::draw_prior<M>(s, data, 3);
    Filter::State x0;
    Filter::Covariance p0;
    mc::initialise(prior, x0, p0);
    filter.reset(x0, p0);
    mc::hal::MarkerPrediction<M> prediction;
    mc::MarkerFrame<M> frame;

    mc::test::AllocCounter armed;
    int frames_done = 0, predicted = 0;
    while (source.poll(frame) == mc::hal::SourceStatus::kOk) {
      if (mc::loop::predict_marker_pixels(filter, frame, prediction)) {
        ++predicted;
        source.relabel(prediction, frame);
      }
      ++frames_done;
    }
    const mc::test::AllocCounts c = armed.stop();
    EXPECT_EQ(frames_done, 40);
    EXPECT_EQ(predicted, 40);
    EXPECT_GT(source.identifier_counters().identified, 60u);
    EXPECT_EQ(c.news, 0);
    EXPECT_EQ(c.mallocs, 0);
  }
}
