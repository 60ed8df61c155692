// `mirrorcal run`'s config file: every key, comments and quotes; each malformed line refused with
// the file, the line and the reason.
#include <gtest/gtest.h>

#include "run_config.hpp"

namespace mirrorcal::app {
namespace {

TEST(RunConfig, ReadsEveryKey) {
  const char* text =
      "# the board in the lab\n"
      "imu: i2c:/dev/i2c-1:0x69   # MPU-6050 at AD0 high\n"
      "drdy: gpiochip0:17\n"
      "trigger: gpiochip0:18\n"
      "trigger-every: 5\n"
      "camera: \"/dev/video2\"\n"
      "\n"
      "sensors: /etc/mirrorcal\n"
      "out: /var/lib/mirrorcal/run-1\n"
      "duration: 90.5\n"
      "rate: 500\n"
      "gyro-range: 1000\n"
      "accel-range: 8\n";
  RunSettings s;
  std::string error;
  ASSERT_TRUE(parse_run_config(text, "run.yaml", s, error)) << error;
  EXPECT_EQ(s.imu, "i2c:/dev/i2c-1:0x69");
  EXPECT_EQ(s.drdy, "gpiochip0:17");
  EXPECT_EQ(s.trigger, "gpiochip0:18");
  EXPECT_EQ(s.trigger_every, 5);
  EXPECT_EQ(s.camera, "/dev/video2");
  EXPECT_EQ(s.sensors, "/etc/mirrorcal");
  EXPECT_EQ(s.out, "/var/lib/mirrorcal/run-1");
  EXPECT_EQ(s.duration_s, 90.5);
  EXPECT_EQ(s.rate_hz, 500.0);
  EXPECT_EQ(s.gyro_range_dps, 1000.0);
  EXPECT_EQ(s.accel_range_g, 8.0);
}

TEST(RunConfig, KeepsDefaultsForWhatIsNotGiven) {
  RunSettings s;
  std::string error;
  ASSERT_TRUE(parse_run_config("imu: can:can0\n", "run.yaml", s, error)) << error;
  const RunSettings d;
  EXPECT_EQ(s.out, d.out);
  EXPECT_EQ(s.duration_s, d.duration_s);
  EXPECT_EQ(s.rate_hz, d.rate_hz);
  EXPECT_TRUE(s.drdy.empty());
  EXPECT_TRUE(s.trigger.empty());
  EXPECT_EQ(s.trigger_every, 0);  // from the camera's frame interval
}

TEST(RunConfig, RefusesMalformedLinesNamingThem) {
  const struct {
    const char* text;
    const char* message;
  } cases[] = {
      {"imu: can:can0\nspeed: 3\n", "run.yaml:2: unknown key 'speed'"},
      {"imu: can:can0\nimu: can:can1\n", "run.yaml:2: 'imu' given twice"},
      {"duration: soon\n", "run.yaml:1: duration: 'soon' is not a duration in seconds (>= 0)"},
      {"duration: -1\n", "run.yaml:1: duration: '-1' is not a duration in seconds (>= 0)"},
      {"rate: 0\n", "run.yaml:1: rate: '0' is not a rate in Hz (> 0)"},
      {"# x\n\nimu can:can0\n", "run.yaml:3: expected `key: value`, got 'imu can:can0'"},
      {"imu:\n", "run.yaml:1: imu: empty value"},
      {"trigger-every: 1\n",
       "run.yaml:1: trigger-every: '1' is not a whole number of IMU samples >= 2 (a pulse lasts "
       "one "
       "IMU period)"},
      {"trigger-every: 2.5\n",
       "run.yaml:1: trigger-every: '2.5' is not a whole number of IMU samples >= 2 (a pulse lasts "
       "one IMU period)"},
  };
  for (const auto& c : cases) {
    RunSettings s;
    std::string error;
    EXPECT_FALSE(parse_run_config(c.text, "run.yaml", s, error)) << c.text;
    EXPECT_EQ(error, c.message);
  }
}

}  // namespace
}  // namespace mirrorcal::app
