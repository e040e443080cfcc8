// The array method with model "full" (SPEC §7, issue #14) through a real server: the simulated
// files of `calibd simulate array --model full` go in, the SPEC result comes out and agrees with
// the truth within the reported σ.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "methods/array/array_method.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

// Every component of est within k σ of truth (σ = 0: an entry fixed by a gauge or the unit
// diagonal, which must then equal the truth).
void ExpectWithin(const json& est, const json& truth, const json& std, double k,
                  const std::string& what) {
  if (est.is_array()) {
    ASSERT_EQ(est.size(), truth.size()) << what;
    for (size_t i = 0; i < est.size(); ++i)
      ExpectWithin(est[i], truth[i], std[i], k, what + "[" + std::to_string(i) + "]");
    return;
  }
  const double s = std.get<double>();
  if (s == 0) {
    EXPECT_NEAR(est.get<double>(), truth.get<double>(), 1e-12) << what;
    return;
  }
  EXPECT_LE(std::abs(est.get<double>() - truth.get<double>()), k * s)
      << what << ": " << est << " vs " << truth << " (σ " << s << ")";
}

TEST(ArrayFullMethod, CalibratesASimulatedBoardThroughTheServerWithinItsUncertainty) {
  ArraySimulationFileOptions sim;
  sim.samples = 600;
  sim.seed = 21;
  sim.gyro_unit = "deg/s";
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFullFiles(sim, &csv, &config, &truth).ok());
  config["device"] = "ARRAY-1";
  TestServer server;
  ASSERT_EQ(server.error(), "");
  json job = server.UploadAndWait(csv, config, "array.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  const json& r = job["result"];
  EXPECT_EQ(r["method"], "array");
  EXPECT_EQ(r["parameters"]["model"], "full");
  const json& d = r["diagnostics"];
  EXPECT_EQ(d["gauge"]["scale"], "sum_trace_gyroscope");
  EXPECT_EQ(d["gauge"]["reference"], 0);
  EXPECT_EQ(d["statics"], 20);
  EXPECT_TRUE(d["converged"].get<bool>());
  EXPECT_NEAR(d["chi2_per_dof"].get<double>(), 1, 0.05);
  EXPECT_EQ(d["noise"]["source"], "configured");
  EXPECT_FALSE(d["robust"]["used"].get<bool>());
  EXPECT_EQ(r["uncertainty"]["basis"], "crb");
  const json& imus = r["parameters"]["imus"];
  const json& stds = r["uncertainty"]["imus"];
  ASSERT_EQ(imus.size(), 8u);
  ASSERT_EQ(stds.size(), 8u);
  // 5σ per entry over 8 × (2 × 15 + 3) entries: wrong units or conventions fail by far.
  for (int k = 0; k < 8; ++k) {
    const json& p = imus[k];
    const json& u = stds[k];
    const json& t = truth["imus"][k];
    EXPECT_EQ(p["name"], std::to_string(k));
    EXPECT_TRUE(u.contains("crb"));
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const std::string what = std::to_string(k) + "." + sensor;
      ExpectWithin(p[sensor]["bias"], t[sensor]["bias"], u[sensor]["bias_std"], 5, what + ".bias");
      ExpectWithin(p[sensor]["scale"], t[sensor]["scale"], u[sensor]["scale_std"], 5,
                   what + ".scale");
      ExpectWithin(p[sensor]["misalignment"], t[sensor]["misalignment"],
                   u[sensor]["misalignment_std"], 5, what + ".misalignment");
      // matrix = misalignment · diag(scale).
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          EXPECT_NEAR(
              p[sensor]["matrix"][i][j].get<double>(),
              p[sensor]["misalignment"][i][j].get<double>() * p[sensor]["scale"][j].get<double>(),
              1e-12);
    }
    ExpectWithin(p["position"], t["position"], u["position_std"], 5,
                 std::to_string(k) + ".position");
  }
  // What the full model changed against the positions-only fit it starts from: that fit's
  // positions plus the change are the full model's, the change in σ is change / position_std
  // (null for the reference, held by the gauge).
  const json& changed = d["changed_from_positions_only"];
  ASSERT_EQ(changed.size(), 8u);
  EXPECT_TRUE(d["positions_only_start"].get<bool>());
  for (int k = 0; k < 8; ++k) {
    const json& c = changed[k];
    ASSERT_TRUE(c.contains("positions_only_std")) << c;
    double norm2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double change = c["position_change"][a].get<double>();
      norm2 += change * change;
      EXPECT_NEAR(c["positions_only"][a].get<double>() + change,
                  imus[k]["position"][a].get<double>(), 1e-12);
      if (k == 0) {
        EXPECT_TRUE(c["position_change_sigma"][a].is_null());
        EXPECT_EQ(change, 0);
      } else {
        EXPECT_NEAR(c["position_change_sigma"][a].get<double>(),
                    change / stds[k]["position_std"][a].get<double>(), 1e-9);
        EXPECT_GT(c["positions_only_std"][a].get<double>(), 0);
      }
    }
    EXPECT_NEAR(c["position_change_norm"].get<double>(), std::sqrt(norm2), 1e-15);
  }
  // The job's HTML report renders a full-model result, with its own sections.
  auto page = server.Client().Get(("/jobs/" + std::to_string(job["id"].get<int64_t>())).c_str());
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  for (const char* part : {"table-array-full-accelerometer", "table-array-full-gyroscope",
                           "plot-array-full-residuals-gyroscope", "table-array-full-change"})
    EXPECT_NE(page->body.find(part), std::string::npos) << part;
  EXPECT_FALSE(r["model"].get<std::string>().empty());
  for (const char* format : {"json", "csv", "h"}) {
    auto exported = server.Client().Get(
        (std::string("/api/v1/devices/ARRAY-1/calibration?method=array&format=") + format).c_str());
    ASSERT_TRUE(exported);
    EXPECT_EQ(exported->status, 200) << format << ": " << exported->body;
  }
  // deg/s readings: the gyroscope matrix maps deg/s to rad/s.
  EXPECT_NEAR(imus[1]["gyroscope"]["scale"][0].get<double>(), M_PI / 180, 0.05 * M_PI / 180);
}

TEST(ArrayFullMethod, ConfigErrorsNameTheKey) {
  ArraySimulationFileOptions sim;
  sim.samples = 50;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFullFiles(sim, &csv, &config, &truth).ok());
  core::ArrayFullProblem p;
  core::ArrayFullOptions o;
  bool deg = false;
  ASSERT_TRUE(ParseArrayFullConfig(config, &p, &o, &deg).ok());
  EXPECT_DOUBLE_EQ(o.statics.static_window, 0.25);
  json c = config;
  c["solver"] = "bcd";
  Status s = ParseArrayFullConfig(c, &p, &o, &deg);
  EXPECT_EQ(s.field(), "solver");
  EXPECT_NE(s.message().find("not used with model \"full\""), std::string::npos);
  c = config;
  c["model"] = "everything";
  core::ArrayProblem pp;
  core::ArrayOptions po;
  s = ParseArrayConfig(c, &pp, &po, &deg);
  EXPECT_EQ(s.field(), "model");
  EXPECT_NE(s.message().find("\"positions\" (default) or \"full\""), std::string::npos);
  c = config;
  c["dynamic_weighting"] = "residual";
  ASSERT_TRUE(ParseArrayFullConfig(c, &p, &o, &deg).ok());
  EXPECT_EQ(o.dynamic_weighting, core::ArrayFullDynamicWeighting::kResidual);
  c["dynamic_weighting"] = "loud";
  EXPECT_EQ(ParseArrayFullConfig(c, &p, &o, &deg).field(), "dynamic_weighting");
  c = config;
  c["accel_noise"] = -1;
  EXPECT_EQ(ParseArrayFullConfig(c, &p, &o, &deg).field(), "accel_noise");
  // Over HTTP a bad key is refused at upload (400, naming it).
  TestServer server;
  c = config;
  c["bogus"] = 1;
  auto res = server.Client().Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", csv, "array.csv", "text/csv"},
                                      {"config", c.dump(), "", "application/json"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  EXPECT_NE(res->body.find("bogus"), std::string::npos) << res->body;
}

}  // namespace
}  // namespace calibd::server
