// The C header export (GET /api/v1/devices/{serial}/calibration?format=h) through a real server:
// headers of two devices and of every method are included together in one C99 program and one
// C++17 program, compiled warning-free, run, and the corrected readings they print are compared
// with the same correction computed here from the result JSON.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "methods/array/array_method.h"
#include "methods/array/array_result.h"
#include "methods/exports.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "methods/pca/pca_method.h"
#include "methods/pca/pca_result.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TempDir;
using testing::TestServer;

// Uploads a recording with its config for `device`; returns the finished job.
json Calibrate(const TestServer& server, const std::string& csv, json config,
               const std::string& device) {
  config["device"] = device;
  return server.UploadAndWait(csv, config, "r.csv");
}

std::string FetchHeader(const TestServer& server, const std::string& serial,
                        const std::string& method) {
  auto res = server.Client().Get(
      ("/api/v1/devices/" + UrlEncode(serial) + "/calibration?method=" + method + "&format=h")
          .c_str());
  if (!res || res->status != 200) {
    ADD_FAILURE() << serial << " " << method << ": " << (res ? res->body : "no answer");
    return "";
  }
  return res->body;
}

// Runs a shell command; its exit status and standard output (stderr folded in).
int RunCommand(const std::string& command, std::string* output) {
  output->clear();
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return -1;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) output->append(buf, n);
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// "key value" lines printed by the test program.
std::map<std::string, double> ParseOutput(const std::string& text) {
  std::map<std::string, double> values;
  std::istringstream in(text);
  std::string key;
  double v;
  while (in >> key >> v) values[key] = v;
  return values;
}

// A raw reading of m sensors: the field `v` seen through the result's sensitivities and biases,
// plus a small perturbation (so the least-squares inverse has a residual to project away).
Eigen::VectorXd PcaReading(const json& result, const Eigen::Vector3d& v) {
  const json& sensors = result["parameters"]["sensors"];
  Eigen::VectorXd r(sensors.size());
  for (size_t i = 0; i < sensors.size(); ++i) {
    const json& a = sensors[i]["sensitivity"];
    r(i) = a[0].get<double>() * v(0) + a[1].get<double>() * v(1) + a[2].get<double>() * v(2) +
           sensors[i]["bias"].get<double>() + 1e-3 * std::sin(1.0 + i);
  }
  return r;
}

// The expected field: the least-squares solution of A v = r − b, from the JSON.
Eigen::Vector3d PcaExpected(const json& result, const Eigen::VectorXd& r) {
  const json& sensors = result["parameters"]["sensors"];
  Eigen::MatrixXd a(sensors.size(), 3);
  Eigen::VectorXd rhs(sensors.size());
  for (size_t i = 0; i < sensors.size(); ++i) {
    for (int k = 0; k < 3; ++k) a(i, k) = sensors[i]["sensitivity"][k].get<double>();
    rhs(i) = r(i) - sensors[i]["bias"].get<double>();
  }
  return a.colPivHouseholderQr().solve(rhs);
}

// matrix (y − bias) of one triad of an imu result.
Eigen::Vector3d ImuExpected(const json& triad, const Eigen::Vector3d& y) {
  Eigen::Matrix3d m;
  Eigen::Vector3d b;
  for (int r = 0; r < 3; ++r) {
    b(r) = triad["bias"][r].get<double>();
    for (int c = 0; c < 3; ++c) m(r, c) = triad["matrix"][r][c].get<double>();
  }
  return m * (y - b);
}

std::string Literal(const Eigen::VectorXd& v) {
  std::string s = "{";
  char buf[40];
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%.17g", v(i));
    s += (i ? ", " : "") + std::string(buf);
  }
  return s + "}";
}

void ExpectClose(const std::map<std::string, double>& out, const std::string& prefix,
                 const Eigen::VectorXd& expected) {
  for (Eigen::Index k = 0; k < expected.size(); ++k) {
    const std::string key = prefix + std::to_string(k);
    auto it = out.find(key);
    ASSERT_NE(it, out.end()) << key;
    EXPECT_LE(std::abs(it->second - expected(k)), 1e-9 * expected.norm())
        << key << ": " << it->second << " vs " << expected(k);
  }
}

TEST(CHeader, HeadersOfTwoDevicesAndEveryMethodCompileTogetherInCAndCxxAndCorrectAReading) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const std::string dev1 = "SN-0001", dev2 = "lab.0002 B";
  std::map<std::string, json> results;  // "device method" -> result

  for (int i = 0; i < 2; ++i) {
    core::PcaSimulationOptions pca;
    pca.positions = 40;
    pca.bias_std = 0.05;
    pca.seed = 11 + i;
    std::string csv;
    json config, truth;
    ASSERT_TRUE(SimulatePcaFiles(pca, &csv, &config, &truth).ok());
    config["bias"] = "estimate";
    json job = Calibrate(server, csv, config, i == 0 ? dev1 : dev2);
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    results[std::to_string(i) + " pca"] = job["result"];

    core::ImuSimulationOptions imu;
    // Random orientations: with these seeds every face of the board is up in some static, so the
    // acceptance gate accepts the result and it is what the device serves (the subject here is
    // the header; the gate's coverage rule has its own tests).
    imu.statics = 24;
    imu.seed = 23 + i;
    ASSERT_TRUE(SimulateImuFiles(imu, &csv, &config, &truth).ok());
    job = Calibrate(server, csv, config, i == 0 ? dev1 : dev2);
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    results[std::to_string(i) + " imu"] = job["result"];
  }
  {
    NoiseSimulationFileOptions noise;
    noise.seconds = 60;
    std::string csv;
    json config, truth;
    ASSERT_TRUE(SimulateNoiseFiles(noise, &csv, &config, &truth).ok());
    json job = Calibrate(server, csv, config, dev1);
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    results["0 noise"] = job["result"];
    ArraySimulationFileOptions array;
    array.samples = 300;
    ASSERT_TRUE(SimulateArrayFiles(array, &csv, &config, &truth).ok());
    job = Calibrate(server, csv, config, dev2);
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    results["1 array"] = job["result"];
  }

  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> headers = {
      {dev1, "pca"}, {dev1, "imu"}, {dev1, "noise"}, {dev2, "pca"}, {dev2, "imu"}, {dev2, "array"}};
  std::string includes;
  for (size_t i = 0; i < headers.size(); ++i) {
    const std::string h = FetchHeader(server, headers[i].first, headers[i].second);
    ASSERT_FALSE(h.empty());
    // The comment states the model; no undefined value is written as a number.
    EXPECT_NE(h.find("Model (" + headers[i].second), std::string::npos) << h;
    EXPECT_EQ(h.find("nan"), std::string::npos) << h;
    EXPECT_EQ(h.find("namespace"), std::string::npos);
    const std::string name = "h" + std::to_string(i) + ".h";
    std::ofstream(dir.path() / name) << h;
    includes += "#include \"" + name + "\"\n";
    // Included twice: the guard holds.
    includes += "#include \"" + name + "\"\n";
  }
  // Every channel's bias instability is invisible in a minute of white noise and random walk:
  // the header says so instead of writing a number.
  const std::string noise_h = FetchHeader(server, dev1, "noise");
  EXPECT_NE(noise_h.find("CALIBD_SN_0001_NOISE_A0_X_BIAS_INSTABILITY is not defined"),
            std::string::npos)
      << noise_h;
  EXPECT_NE(noise_h.find("#define CALIBD_SN_0001_NOISE_A0_X_WHITE_NOISE "), std::string::npos);

  const Eigen::Vector3d v1(0.3, -0.5, 0.8), v2(-0.7, 0.1, 0.6);
  const Eigen::VectorXd r1 = PcaReading(results["0 pca"], v1);
  const Eigen::VectorXd r2 = PcaReading(results["1 pca"], v2);
  const Eigen::Vector3d ya(0.2, -9.7, 0.4), yg(0.05, -0.02, 0.3);
  const std::string program = includes + R"(
#include <stdio.h>

static void print(const char* key, const double* v, int n) {
  int k;
  for (k = 0; k < n; ++k) printf("%s%d %.17g\n", key, k, v[k]);
}

int main(void) {
  const double r1[CALIBD_SN_0001_PCA_SENSORS] = )" +
                              Literal(r1) + R"(;
  const double r2[CALIBD_LAB_0002_B_PCA_SENSORS] = )" +
                              Literal(r2) + R"(;
  const double ya[3] = )" + Literal(ya) +
                              R"(, yg[3] = )" + Literal(yg) + R"(;
  double v[3], a[3], w[3];
  calibd_sn_0001_pca_apply(r1, v);
  print("pca1_", v, 3);
  calibd_lab_0002_b_pca_apply(r2, v);
  print("pca2_", v, 3);
  if (calibd_sn_0001_imu_apply(0, ya, yg, a, w) != 0) return 1;
  print("imu1_a", a, 3);
  print("imu1_w", w, 3);
  if (calibd_lab_0002_b_imu_apply(0, ya, yg, a, w) != 0) return 1;
  print("imu2_a", a, 3);
  print("imu2_w", w, 3);
  if (calibd_lab_0002_b_imu_apply(CALIBD_LAB_0002_B_IMU_IMUS, ya, yg, a, w) != -1) return 1;
  printf("job1 %lld\n", CALIBD_SN_0001_PCA_JOB_ID);
  printf("array_y1 %.17g\n", CALIBD_LAB_0002_B_ARRAY_POSITION[1][1]);
  printf("noise_n %.17g\n", CALIBD_SN_0001_NOISE_G0_Z_WHITE_NOISE);
  printf("noise_channels %d\n", CALIBD_SN_0001_NOISE_CHANNELS);
  printf("devices_differ %d\n", CALIBD_SN_0001_PCA_DEVICE[0] != CALIBD_LAB_0002_B_PCA_DEVICE[0]);
  return 0;
}
)";
  std::ofstream(dir.path() / "main.c") << program;
  std::ofstream(dir.path() / "main.cc") << program;

  const std::string d = dir.path().string();
  const std::vector<std::pair<std::string, std::string>> builds = {
      {"C99", "gcc -std=c99 -Wall -Wextra -Werror -pedantic -o " + d + "/c " + d + "/main.c"},
      {"C++17", "g++ -std=c++17 -Wall -Wextra -Werror -o " + d + "/cxx " + d + "/main.cc"}};
  for (const auto& [language, command] : builds) {
    SCOPED_TRACE(language);
    std::string output;
    ASSERT_EQ(RunCommand(command, &output), 0) << output;
    const std::string exe = d + (language == "C99" ? "/c" : "/cxx");
    ASSERT_EQ(RunCommand(exe, &output), 0) << output;
    const auto out = ParseOutput(output);
    ExpectClose(out, "pca1_", PcaExpected(results["0 pca"], r1));
    ExpectClose(out, "pca2_", PcaExpected(results["1 pca"], r2));
    // The pca field comes back close to the one that made the reading (the perturbation is
    // small against the sensitivities), so the header's inverse is the right one.
    EXPECT_NEAR(out.at("pca1_0"), v1(0), 0.01);
    const json& imu1 = results["0 imu"]["parameters"]["imus"][0];
    const json& imu2 = results["1 imu"]["parameters"]["imus"][0];
    ExpectClose(out, "imu1_a", ImuExpected(imu1["accelerometer"], ya));
    ExpectClose(out, "imu1_w", ImuExpected(imu1["gyroscope"], yg));
    ExpectClose(out, "imu2_a", ImuExpected(imu2["accelerometer"], ya));
    ExpectClose(out, "imu2_w", ImuExpected(imu2["gyroscope"], yg));
    EXPECT_EQ(out.at("array_y1"),
              results["1 array"]["parameters"]["positions"][1]["position"][1].get<double>());
    EXPECT_EQ(out.at("noise_n"),
              results["0 noise"]["parameters"]["channels"][5]["white_noise"].get<double>());
    EXPECT_EQ(out.at("noise_channels"), 6);
    EXPECT_EQ(out.at("devices_differ"), 1);
    EXPECT_GT(out.at("job1"), 0);
  }
}

// Two jobs of the same device and method are different calibrations: including both is a
// compile error, never one silently shadowing the other.

// A pca result (methods/pca/pca_result.h, every key) of one sensor in a 1-d field: sensitivity 2,
// the given bias, an undefined σ(scale).
json OneSensorPcaResult(const std::string& name, bool magnitude_known, double bias) {
  results::PcaResult r;
  r.envelope.method = "pca";
  r.envelope.model = "r = a v + b";
  results::PcaParameters p;
  p.dimension = 1;
  p.magnitude = 1.0;
  p.magnitude_known = magnitude_known;
  p.frame = results::PcaFrame::kCanonical;
  p.sensors = {{name, {2.0}, 2.0, {1.0}, bias}};
  r.parameters = p;
  r.uncertainty =
      results::PcaUncertainty{{{name, results::kPcaNaN, 1e-3, 0.0, std::nullopt}}, 0.01};
  r.diagnostics.usable = true;
  return results::ToJson(r);
}

TEST(CHeader, TwoCalibrationsOfOneDeviceAndMethodCollideLoudly) {
  const json result = OneSensorPcaResult("s1", true, 0.5);
  std::string h1, h2;
  ASSERT_TRUE(ResultToHeader(result, {1, "SN-1", "pca", "2026-01-01T00:00:00Z"}, &h1).ok());
  ASSERT_TRUE(ResultToHeader(result, {2, "SN-1", "pca", "2026-01-02T00:00:00Z"}, &h2).ok());
  // An undefined σ is left out with a comment, not written as 0.
  EXPECT_NE(h1.find("CALIBD_SN_1_PCA_SCALE_STD is not written"), std::string::npos) << h1;
  EXPECT_EQ(h1.find("CALIBD_SN_1_PCA_SCALE_STD["), std::string::npos) << h1;
  TempDir dir;
  std::ofstream(dir.path() / "a.h") << h1;
  std::ofstream(dir.path() / "b.h") << h2;
  std::ofstream(dir.path() / "one.c")
      << "#include \"a.h\"\n#include <stdio.h>\nint main(void) { double v[1]; const double r[1] = "
         "{4.5}; calibd_sn_1_pca_apply(r, v); printf(\"%.17g\\n\", v[0]); return 0; }\n";
  std::ofstream(dir.path() / "two.c") << "#include \"a.h\"\n#include \"b.h\"\nint main(void) { "
                                         "return 0; }\n";
  const std::string d = dir.path().string();
  std::string output;
  ASSERT_EQ(
      RunCommand("gcc -std=c99 -Wall -Werror -pedantic -o " + d + "/one " + d + "/one.c", &output),
      0)
      << output;
  ASSERT_EQ(RunCommand(d + "/one", &output), 0);
  EXPECT_EQ(std::stod(output), 2.0);  // (4.5 − 0.5) / 2
  EXPECT_NE(RunCommand("gcc -std=c99 -Wall -Werror -pedantic -c -o " + d + "/two.o " + d + "/two.c",
                       &output),
            0);
  EXPECT_NE(output.find("redefinition"), std::string::npos) << output;
}

// A serial or sensor name from a user cannot end a comment, open one, form a trigraph or break a
// string literal: the header still compiles warning-free and holds the names unchanged.
TEST(CHeader, HostileSerialAndSensorNamesCannotBreakTheHeader) {
  const std::string serial = "x*/ int evil; /*?\?/\"\\";
  const std::string sensor = "s?\?=1*/\"";
  // (The frame, once a string a hostile result could fill, is an enum of the typed result: a
  // result with another frame does not read, so it never reaches the header.)
  const json result = OneSensorPcaResult(sensor, false, 0.0);
  std::string h;
  ASSERT_TRUE(ResultToHeader(result, {7, serial, "pca", "2026-01-01T00:00:00Z"}, &h).ok());
  TempDir dir;
  std::ofstream(dir.path() / "h.h") << h;
  std::ofstream(dir.path() / "main.c")
      << "#include \"h.h\"\n#include <string.h>\nint main(void) {\n"
         "  static const char expected_serial[] = \"x*/ int evil; /*\\?\\?/\\\"\\\\\";\n"
         "  static const char expected_sensor[] = \"s\\?\\?=1*/\\\"\";\n"
         "  return strcmp(CALIBD_X___INT_EVIL__________PCA_DEVICE, expected_serial) != 0 ||\n"
         "         strcmp(CALIBD_X___INT_EVIL__________PCA_NAMES[0], expected_sensor) != 0;\n"
         "}\n";
  const std::string d = dir.path().string();
  std::string output;
  for (const std::string compiler : {"gcc -std=c99 -Wall -Wextra -Werror -pedantic -x c",
                                     "g++ -std=c++17 -Wall -Wextra -Werror -x c++"}) {
    ASSERT_EQ(RunCommand(compiler + " -o " + d + "/main " + d + "/main.c", &output), 0)
        << compiler << "\n"
        << output << "\n"
        << h;
    EXPECT_EQ(RunCommand(d + "/main", &output), 0) << compiler;
  }
}

// An array result of the full model (per-IMU intrinsics beside the positions, SPEC §7) gets the
// imu apply function too, without clashing with the positions' names.
TEST(CHeader, ArrayResultWithIntrinsicsAppliesThemToAReading) {
  // A full-model result (methods/array/array_result.h) whose two triads read y -> matrix (y -
  // bias), the position sigma undefined.
  results::SensorTriad triad;
  triad.bias = {0.1, -0.2, 0.3};
  triad.matrix << 2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.5, 4.0;
  results::ArrayResult typed;
  typed.envelope.method = "array";
  typed.envelope.model = "full";
  typed.full = true;
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  params.positions = {{"a0", {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}},
                      {"a1", {0.01, 0.0, 0.0}, {0.001, 0.0, 0.0}}};
  for (const char* name : {"0", "1"}) {
    results::ArrayImu imu;
    imu.triads = {name, triad, triad};
    imu.position = Eigen::Vector3d::Zero();
    params.imus.push_back(imu);
    results::ArrayImuStd s;
    s.triads.name = name;
    unc.imus.push_back(s);
    unc.positions.push_back({name, Eigen::Vector3d::Constant(NAN), std::nullopt});
  }
  typed.parameters = params;
  typed.uncertainty = unc;
  const json result = results::ToJson(typed);
  std::string h;
  ASSERT_TRUE(ResultToHeader(result, {3, "B-1", "array", "2026-01-01T00:00:00Z"}, &h).ok());
  EXPECT_NE(h.find("POSITION_STD is not written"), std::string::npos) << h;
  TempDir dir;
  std::ofstream(dir.path() / "h.h") << h;
  std::ofstream(dir.path() / "main.c")
      << "#include \"h.h\"\n#include <stdio.h>\nint main(void) {\n"
         "  const double y[3] = {1.1, 0.8, 1.3};\n  double a[3], w[3];\n"
         "  if (calibd_b_1_array_apply(1, y, y, a, w) != 0) return 1;\n"
         "  printf(\"%.17g %.17g %.17g %d %d\\n\", a[0], a[1], a[2], CALIBD_B_1_ARRAY_IMU_IMUS,\n"
         "         CALIBD_B_1_ARRAY_TRIADS);\n  return 0;\n}\n";
  const std::string d = dir.path().string();
  std::string output;
  ASSERT_EQ(
      RunCommand("gcc -std=c99 -Wall -Wextra -Werror -pedantic -o " + d + "/main " + d + "/main.c",
                 &output),
      0)
      << output << "\n"
      << h;
  ASSERT_EQ(RunCommand(d + "/main", &output), 0);
  // matrix (y - bias): (2·1, 3·1, 0.5·1 + 4·1).
  double a0, a1, a2;
  int imus, triads;
  ASSERT_EQ(std::sscanf(output.c_str(), "%lf %lf %lf %d %d", &a0, &a1, &a2, &imus, &triads), 5);
  EXPECT_DOUBLE_EQ(a0, 2.0);
  EXPECT_DOUBLE_EQ(a1, 3.0);
  EXPECT_DOUBLE_EQ(a2, 4.5);
  EXPECT_EQ(imus, 2);
  EXPECT_EQ(triads, 2);
}

// Issue 27: two non-ASCII serials that differ only where transliteration writes '_' (case of Ü,
// ß vs ß, the CJK bytes) get identifiers of their own: both headers compile into one program,
// and each keeps its own serial. An ASCII serial keeps the plain stem (no hash), so existing
// firmware code that names CALIBD_SN_1_PCA_... still builds.
TEST(CHeader, NonAsciiSerialsThatTransliterateAlikeDoNotCollide) {
  const json result = OneSensorPcaResult("s1", true, 0.5);
  std::string h1, h2, ascii;
  ASSERT_TRUE(
      ResultToHeader(result, {1, "Drohne-\u00dc\u00df-\u6e2c\u8a66", "pca", "t"}, &h1).ok());
  ASSERT_TRUE(
      ResultToHeader(result, {2, "drohne-\u00fc\u00df-\u6e2c\u8a66", "pca", "t"}, &h2).ok());
  ASSERT_TRUE(ResultToHeader(result, {3, "SN-1", "pca", "t"}, &ascii).ok());
  EXPECT_NE(ascii.find("#define CALIBD_SN_1_PCA_JOB_ID"), std::string::npos) << ascii;
  EXPECT_NE(ascii.find("#define CALIBD_SN_1_PCA_ACCEPTED 1"), std::string::npos) << ascii;
  TempDir dir;
  std::ofstream(dir.path() / "a.h") << h1;
  std::ofstream(dir.path() / "b.h") << h2;
  std::ofstream(dir.path() / "both.c") << "#include \"a.h\"\n#include \"b.h\"\nint main(void) { "
                                          "return 0; }\n";
  const std::string d = dir.path().string();
  std::string output;
  EXPECT_EQ(
      RunCommand("gcc -std=c99 -Wall -Werror -pedantic -c -o " + d + "/both.o " + d + "/both.c",
                 &output),
      0)
      << output << "\n"
      << h1.substr(0, 1200);
}

}  // namespace
}  // namespace calibd::server
