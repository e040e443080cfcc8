// Statics through the methods (issue #20): a log whose statics last 2 s at 62.5 Hz calibrates
// with the default 1 s window and minimum (it found 0 statics before), and when too few statics
// are found the imu and array full messages say what was found (the still stretches and their
// lengths, the threshold) and what to change.
#include <gtest/gtest.h>

#include <string>

#include "core/imu_simulation.h"
#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "server/config.h"

namespace calibd::server {
namespace {

using nlohmann::json;

TEST(StaticsMessage, TwoSecondStaticsAt62HzCalibrate) {
  for (double noise : {1.0, 0.0}) {
    core::ImuSimulationOptions o;
    o.rate = 62.5;
    o.statics = 20;
    o.static_duration = 2;
    o.seed = 4;
    o.accel_noise *= noise;
    o.gyro_noise *= noise;
    std::string csv;
    json config, truth, result;
    ASSERT_TRUE(SimulateImuFiles(o, &csv, &config, &truth).ok());
    if (noise == 0) {
      config["accel_noise"] = 0.01;
      config["gyro_noise"] = 0.002;
    }
    const Status s = Calibrate(csv, "imu.csv", config, &result);
    ASSERT_TRUE(s.ok()) << "noise " << noise << ": " << s.message();
    EXPECT_EQ(result.at("diagnostics").at("statics").size(), 20u) << "noise " << noise;
  }
}

TEST(StaticsMessage, ImuSaysWhatWasFoundAndWhatToChange) {
  core::ImuSimulationOptions o;
  o.statics = 12;
  o.static_duration = 1.5;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateImuFiles(o, &csv, &config, &truth).ok());
  config["min_static"] = 2;
  const Status s = Calibrate(csv, "imu.csv", config, &result);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_EQ(s.reason(), Reason::kTooFewStatics);
  for (const char* part : {"found 0 static intervals", "min_static 2 s", "threshold",
                           "12 still stretch(es) shorter "
                           "than min_static (1.",
                           "lower min_static"}) {
    EXPECT_NE(s.message().find(part), std::string::npos) << part << " not in: " << s.message();
  }
}

TEST(StaticsMessage, ArrayFullSaysWhatWasFoundAndWhatToChange) {
  ArraySimulationFileOptions o;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(o, &csv, &config, &truth).ok());
  config["min_static"] = 5;  // the simulated statics last 1.5 s
  const Status s = Calibrate(csv, "array.csv", config, &result);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_EQ(s.reason(), Reason::kTooFewStatics);
  for (const char* part :
       {"the log has 0", "static detection (static_window 0.25 s, min_static 5 s",
        "still stretch(es) shorter than min_static", "lower min_static"}) {
    EXPECT_NE(s.message().find(part), std::string::npos) << part << " not in: " << s.message();
  }
}

}  // namespace
}  // namespace calibd::server
