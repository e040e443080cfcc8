// The device page's drift of the thermal curves (methods/thermal/thermal_drift.h), on results the
// real method computes from simulated warm-ups with a known truth: the same unit calibrated twice
// is not marked; a gyroscope whose curve moved is marked on that sensor, with the change where it
// is largest; logs that share no range and results that do not read are said so.
#include "methods/thermal/thermal_drift.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/thermal.h"
#include "core/thermal_simulation.h"
#include "methods/thermal/thermal_method.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

size_t Count(const std::string& page, const std::string& needle) {
  size_t n = 0;
  for (size_t p = page.find(needle); p != std::string::npos; p = page.find(needle, p + 1)) ++n;
  return n;
}

// A warm-up of one IMU "0" from t0 by 40 °C (truth: DefaultThermalTruth(3)), its gyroscope x
// curve's first coefficient raised by `gyro_x_slope`, calibrated by the real method; the result
// JSON.
json Calibration(uint64_t seed, double gyro_x_slope = 0, double t0 = 20) {
  core::ThermalSimulationOptions o;
  o.rate = 20;
  o.warmup = 1800;
  o.t0 = t0;
  o.seed = seed;
  o.coefficients = core::DefaultThermalTruth(3);
  o.coefficients[3](0) += gyro_x_slope;
  const core::ThermalSimulation sim = core::SimulateThermal(o);
  const std::vector<core::ThermalImuInput> imus = {{"0", &sim.accel, &sim.gyro, &sim.temp}};
  core::ThermalOptions options;
  core::ThermalResult r;
  const Status s = core::CalibrateThermal(sim.t, imus, options, &r);
  EXPECT_TRUE(s.ok()) << s.message();
  return server::ThermalResultToJson(r, options);
}

JobSummary Job(int64_t id, const std::string& created, json result) {
  JobSummary j;
  j.id = id;
  j.device = "IMU-9";
  j.method = "thermal";
  j.status = JobStatus::kSucceeded;
  j.created_at = j.started_at = j.finished_at = created;
  j.attempts = 1;
  j.result = std::move(result);
  return j;
}

TEST(ThermalDrift, TheSameUnitTwiceIsNotMarkedAndAMovedGyroscopeCurveIs) {
  // 1e-4 rad/s/°C more on gyroscope x: 2e-3 rad/s across ±10 °C, far beyond the σ of a 30-minute
  // warm-up's curve (~1e-5 rad/s).
  const JobSummary a = Job(4, "2026-01-01T00:00:00Z", Calibration(1));
  const JobSummary b = Job(7, "2026-02-01T00:00:00Z", Calibration(2));
  const JobSummary c = Job(9, "2026-03-01T00:00:00Z", Calibration(3, 1e-4));
  const std::string html = ThermalDriftHtml({&a, &b, &c});
  EXPECT_EQ(Count(html, "<table class=\"table-drift-thermal\""), 1u);
  EXPECT_EQ(Count(html, ">first</td>"), 3u);  // job 4: three change cells
  for (const char* id : {"/jobs/4\"", "/jobs/7\"", "/jobs/9\""}) EXPECT_EQ(Count(html, id), 1u);
  // Only job 9's gyroscope cells are marked: the curve (its x axis), and the absolute bias at
  // t_ref (the logs share t_ref within 0.05 °C here), which a slope change moves by 1e-4 ×
  // (t_ref − 35 °C, the truth's reference).
  EXPECT_EQ(Count(html, "drift-significant"), 2u) << html;
  const size_t marked = html.find("drift-significant");
  EXPECT_GT(marked, html.find("/jobs/9\""));
  // The shape change is largest at the common range's upper end (~58 °C): 1e-4 × (58 − 39) ≈
  // +1.9e-3 rad/s, x the only axis that moved.
  const std::string cell = html.substr(marked, html.find("</td>", marked) - marked);
  EXPECT_NE(cell.find("<strong>x +0.001"), std::string::npos) << cell;
  EXPECT_NE(cell.find(" at 5"), std::string::npos) << cell;
  EXPECT_EQ(Count(html, "class=\"plot plot-drift-thermal-gyro\""), 1u);
  EXPECT_EQ(Count(html, "class=\"plot plot-drift-thermal-accel\""), 1u);
  EXPECT_NE(html.find("gyroscope x: curve of each calibration"), std::string::npos);
}

TEST(ThermalDrift, LogsWithoutACommonRangeAreNotComparedAndBrokenResultsAreListed) {
  const JobSummary a = Job(1, "2026-01-01T00:00:00Z", Calibration(1, 0, 0));
  const JobSummary b = Job(2, "2026-01-02T00:00:00Z", Calibration(2, 0, 45));
  json broken = Calibration(3);
  broken["uncertainty"]["imus"][0]["gyroscope"]["bias"]["covariance"][1] = json::array();
  const JobSummary c = Job(3, "2026-01-03T00:00:00Z", broken);
  const std::string html = ThermalDriftHtml({&a, &b, &c});
  // Job 1 spans ~0–40 °C, job 2 ~45–85 °C.
  EXPECT_EQ(Count(html, "ranges overlap by less than 1"), 2u) << html;
  EXPECT_EQ(Count(html, "drift-unreadable"), 1u);
  EXPECT_NE(html.find("covariance does not match"), std::string::npos);
  EXPECT_NE(html.find("the calibrations share no temperature range"), std::string::npos);
}

}  // namespace
}  // namespace calibd::web
