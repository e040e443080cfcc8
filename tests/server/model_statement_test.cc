// Every method states its model (the equation that maps a raw reading to the calibrated
// quantity) in the result JSON's `model` key, and the job's HTML report shows it.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "methods/pca/pca_method.h"
#include "tests/server/http_test_util.h"
#include "web/html.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

TEST(ModelStatement, EveryMethodsResultAndReportStateTheEquation) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  struct Case {
    std::string method, csv;
    json config;
    std::string equation;  // a part of the model that only the right equation has
  };
  std::vector<Case> cases(4);
  json truth;
  {
    core::PcaSimulationOptions o;
    o.positions = 20;
    cases[0].method = "pca";
    ASSERT_TRUE(SimulatePcaFiles(o, &cases[0].csv, &cases[0].config, &truth).ok());
    cases[0].equation = "r_i = a_i^T v + b_i";
  }
  {
    ArraySimulationFileOptions o;
    o.samples = 200;
    cases[1].method = "array";
    ASSERT_TRUE(SimulateArrayFiles(o, &cases[1].csv, &cases[1].config, &truth).ok());
    cases[1].equation = "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k";
  }
  {
    core::ImuSimulationOptions o;
    o.statics = 12;
    cases[2].method = "imu";
    ASSERT_TRUE(SimulateImuFiles(o, &cases[2].csv, &cases[2].config, &truth).ok());
    cases[2].equation = "a = T_a K_a (y_a - b_a), omega = T_g K_g (y_g - b_g)";
  }
  {
    NoiseSimulationFileOptions o;
    o.seconds = 30;
    cases[3].method = "noise";
    ASSERT_TRUE(SimulateNoiseFiles(o, &cases[3].csv, &cases[3].config, &truth).ok());
    cases[3].equation = "sigma^2(tau) = N^2/tau + (0.664 B)^2 + K^2 tau/3";
  }
  for (Case& c : cases) {
    SCOPED_TRACE(c.method);
    c.config["device"] = "MODEL-1";
    const json job = server.UploadAndWait(c.csv, c.config, "r.csv");
    ASSERT_FALSE(job.is_null());
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    const json& model = job["result"]["model"];
    ASSERT_TRUE(model.is_string());
    EXPECT_NE(model.get<std::string>().find(c.equation), std::string::npos) << model;
    const int64_t id = job["id"];
    auto page = server.Client().Get(("/jobs/" + std::to_string(id)).c_str());
    ASSERT_TRUE(page);
    ASSERT_EQ(page->status, 200);
    EXPECT_NE(page->body.find("<p class=\"model\">" + web::EscapeText(model.get<std::string>())),
              std::string::npos);
  }
}

}  // namespace
}  // namespace calibd::server
