// The camera trigger driven from the IMU stream: one pulse per `every` samples, one IMU period
// long, no redundant writes to the line, the line left inactive at the end, and a line that fails
// ending the stream with its own message.
#include <gtest/gtest.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "mirrorcal/loop/triggering_imu.hpp"

namespace mc = mirrorcal;
using mc::loop::TriggeringImu;

namespace {

// Samples 0, 1, 2, ... 5 ms apart, `count` of them, then the end of the stream (or an error).
struct CountingImu final : mc::hal::ImuSource {
  int count = 0, delivered = 0;
  bool fail_at_end = false;
  mc::hal::SourceStatus next(mc::ImuSample& s) override {
    if (delivered == count)
      return fail_at_end ? mc::hal::SourceStatus::kError : mc::hal::SourceStatus::kEndOfStream;
    s.t_ns = 5'000'000LL * delivered++;
    return mc::hal::SourceStatus::kOk;
  }
  const char* error() const override { return "spi:/dev/spidev0.0: stops answering"; }
};

// Every write, with the number of samples the IMU had delivered when it came; fails from the
// write numbered fail_from on.
struct RecordingLine final : mc::hal::OutputLine {
  const CountingImu* imu = nullptr;
  std::vector<std::pair<int, bool>> writes;
  int fail_from = -1;
  bool set(bool active) override {
    if (fail_from >= 0 && static_cast<int>(writes.size()) >= fail_from) return false;
    writes.emplace_back(imu->delivered, active);
    return true;
  }
  const char* error() const override { return "gpiochip0:18: setting the line failed: EIO"; }
};

}  // namespace

TEST(TriggeringImu, PulsesEveryNthSampleForOneImuPeriod) {
  CountingImu imu;
  imu.count = 12;
  RecordingLine line;
  line.imu = &imu;
  {
    TriggeringImu triggering(imu, line, 4);
    mc::ImuSample s;
    int samples = 0;
    while (triggering.next(s) == mc::hal::SourceStatus::kOk) {
      EXPECT_EQ(s.t_ns, 5'000'000LL * samples);  // the stream passes through unchanged
      ++samples;
    }
    EXPECT_EQ(samples, 12);
    EXPECT_EQ(triggering.pulses(), 3u);
  }
  // Active with samples 1, 5, 9 delivered (the first of every four), inactive with the next: and
  // nothing written in between.
  const std::vector<std::pair<int, bool>> expected = {{1, true},  {2, false}, {5, true},
                                                      {6, false}, {9, true},  {10, false}};
  EXPECT_EQ(line.writes, expected);
}

TEST(TriggeringImu, LeavesTheLineInactiveWhenTheStreamEndsMidPulse) {
  CountingImu imu;
  imu.count = 9;  // the last sample fires the trigger
  RecordingLine line;
  line.imu = &imu;
  {
    TriggeringImu triggering(imu, line, 4);
    mc::ImuSample s;
    while (triggering.next(s) == mc::hal::SourceStatus::kOk) {
    }
    ASSERT_FALSE(line.writes.empty());
    EXPECT_TRUE(line.writes.back().second);
  }
  EXPECT_FALSE(line.writes.back().second);
}

TEST(TriggeringImu, ALineThatFailsEndsTheStreamWithItsMessage) {
  CountingImu imu;
  imu.count = 100;
  RecordingLine line;
  line.imu = &imu;
  line.fail_from = 2;  // the second pulse's rising edge, with the fourth sample
  TriggeringImu triggering(imu, line, 3);
  mc::ImuSample s;
  int ok = 0;
  mc::hal::SourceStatus st;
  while ((st = triggering.next(s)) == mc::hal::SourceStatus::kOk) ++ok;
  EXPECT_EQ(st, mc::hal::SourceStatus::kError);
  EXPECT_EQ(ok, 3);
  EXPECT_EQ(std::string(triggering.error()), "gpiochip0:18: setting the line failed: EIO");
  const int delivered = imu.delivered;
  EXPECT_EQ(triggering.next(s), mc::hal::SourceStatus::kError);  // stays failed
  EXPECT_EQ(imu.delivered, delivered);
}

TEST(TriggeringImu, TheImusOwnEndAndErrorsPassThrough) {
  CountingImu imu;
  imu.count = 2;
  imu.fail_at_end = true;
  RecordingLine line;
  line.imu = &imu;
  TriggeringImu triggering(imu, line, 1);
  EXPECT_EQ(triggering.every(), 2);  // a pulse lasts one period: at most every other sample
  mc::ImuSample s;
  EXPECT_EQ(triggering.next(s), mc::hal::SourceStatus::kOk);
  EXPECT_EQ(triggering.next(s), mc::hal::SourceStatus::kOk);
  EXPECT_EQ(triggering.next(s), mc::hal::SourceStatus::kError);
  EXPECT_EQ(std::string(triggering.error()), "spi:/dev/spidev0.0: stops answering");
}

// The markers' LEDs blinking their names: before pulse n rises, each LED is as the code has it in
// frame n (hal/blink_code.hpp), only the lines that change written; a failing LED line ends the
// stream with its own message.
TEST(TriggeringImu, SetsTheLedsAsTheirCodeHasItBeforeEachPulse) {
  constexpr int kLeds = 3;
  CountingImu imu;
  imu.count = 4 * 12;
  RecordingLine trigger;
  trigger.imu = &imu;
  std::array<RecordingLine, kLeds> leds;
  std::array<mc::hal::OutputLine*, kLeds> lines{};
  for (int i = 0; i < kLeds; ++i) {
    leds[std::size_t(i)].imu = &imu;
    lines[std::size_t(i)] = &leds[std::size_t(i)];
  }
  const mc::hal::BlinkCode code{5};
  mc::loop::BlinkingLeds blinking(lines.data(), kLeds, code);
  TriggeringImu triggering(imu, trigger, 4, &blinking);
  mc::ImuSample s;
  while (triggering.next(s) == mc::hal::SourceStatus::kOk) {
  }
  ASSERT_EQ(triggering.pulses(), 12u);
  // The level of each LED when each pulse rose (the LEDs start lit).
  for (std::uint32_t pulse = 0; pulse < 12; ++pulse) {
    const int rose_with = static_cast<int>(4 * pulse + 1);  // samples delivered at the rising edge
    for (int i = 0; i < kLeds; ++i) {
      bool lit = true;
      for (const auto& [delivered, level] : leds[std::size_t(i)].writes)
        if (delivered <= rose_with) lit = level;
      EXPECT_EQ(lit, code.lit(i, kLeds, pulse)) << "LED " << i << ", pulse " << pulse;
    }
  }
  // Each LED dark once and lit again once per period of five pulses: two writes per period.
  for (const RecordingLine& led : leds) EXPECT_LE(led.writes.size(), 2u * (12 / 5 + 1));
}

TEST(TriggeringImu, AnLedLineThatFailsEndsTheStreamWithItsMessage) {
  struct FailingLed final : mc::hal::OutputLine {
    bool set(bool) override { return false; }
    const char* error() const override { return "gpiochip0:5: setting the line failed: EBUSY"; }
  };
  CountingImu imu;
  imu.count = 100;
  RecordingLine trigger;
  trigger.imu = &imu;
  FailingLed led;
  mc::hal::OutputLine* line = &led;
  mc::loop::BlinkingLeds blinking(&line, 1, mc::hal::BlinkCode{4});
  TriggeringImu triggering(imu, trigger, 2, &blinking);
  mc::ImuSample s;
  int ok = 0;
  while (triggering.next(s) == mc::hal::SourceStatus::kOk) ++ok;
  EXPECT_EQ(ok, 2);  // pulse 1 (LED 0 dark) fails, with the third sample
  EXPECT_EQ(std::string(triggering.error()), "gpiochip0:5: setting the line failed: EBUSY");
}
