// JsonReader and Envelope: typed reads that name the path of the first problem, the NaN/null
// convention, and the schema version rules every method's result follows.
#include "results/json_reader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "results/envelope.h"
#include "results/triad.h"

namespace calibd::results {
namespace {

using nlohmann::json;

const json kDoc = json::parse(R"({
  "parameters": {"sensors": [{"name": "a", "scale": 2.5}, {"name": "b", "scale": "x"}],
                 "count": 3, "flag": true, "big": 3.5, "v": [1, null, 3],
                 "m": [[1, 2, 3], [4, 5, 6], [7, 8, 9]], "short": [1, 2]},
  "nothing": null
})");

struct Sensor {
  std::string name;
  double scale = 0;
};

TEST(JsonReader, ReadsTypedValuesAndNullAsNaN) {
  JsonReader r(kDoc, "test result");
  JsonReader p = r.Object("parameters");
  int count = 0;
  bool flag = false;
  std::vector<double> v;
  Eigen::Matrix3d m;
  p.Read("count", &count);
  p.Read("flag", &flag);
  p.Read("v", &v);
  p.Read("m", &m);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(count, 3);
  EXPECT_TRUE(flag);
  ASSERT_EQ(v.size(), 3u);
  EXPECT_EQ(v[0], 1);
  EXPECT_TRUE(std::isnan(v[1]));
  EXPECT_EQ(m(1, 2), 6);
  EXPECT_EQ(m(2, 0), 7);
}

TEST(JsonReader, NamesThePathOfAWrongTypeInAnArrayOfObjects) {
  JsonReader r(kDoc, "test result");
  std::vector<Sensor> sensors;
  r.Object("parameters").ReadArray("sensors", &sensors, [](const JsonReader& e, Sensor* s) {
    e.Read("name", &s->name);
    e.Read("scale", &s->scale);
  });
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidInput);
  EXPECT_EQ(r.status().field(), "parameters.sensors[1].scale");
  EXPECT_NE(r.status().message().find("test result: parameters.sensors[1].scale: expected a "
                                      "number, found a string"),
            std::string::npos)
      << r.status().message();
  EXPECT_TRUE(sensors.empty()) << "a failed read leaves the output untouched";
}

TEST(JsonReader, KeepsTheFirstProblemAndLeavesLaterOutputsUntouched) {
  JsonReader r(kDoc, "doc");
  double missing = 7;
  int not_integral = 5;
  r.Object("parameters").Read("absent", &missing);
  r.Object("parameters").Read("big", &not_integral);
  EXPECT_EQ(r.status().field(), "parameters.absent");
  EXPECT_NE(r.status().message().find("missing"), std::string::npos);
  EXPECT_EQ(missing, 7);
  EXPECT_EQ(not_integral, 5);
}

TEST(JsonReader, RefusesANonIntegralNumberWhereAnIntegerBelongs) {
  JsonReader r(kDoc, "doc");
  int64_t n = 0;
  r.Object("parameters").Read("big", &n);
  EXPECT_EQ(r.status().field(), "parameters.big");
  EXPECT_NE(r.status().message().find("expected an integer, found 3.5"), std::string::npos);
}

// An array of integers takes each element by the scalar's rule: a float too large to be the
// integer it was written as, an unsigned beyond int64 or a string is refused naming its index.
TEST(JsonReader, IntegerArraysRefuseWhatAnIntegerWouldNamingTheElement) {
  for (const auto& [element, why] : std::vector<std::pair<nlohmann::json, std::string>>{
           {1e300, "expected an integer, found 1e+300"},
           {18446744073709551615ull, "integer out of range: 18446744073709551615"},
           {"7", "expected an integer, found a string"},
           {2.5, "expected an integer, found 2.5"}}) {
    const nlohmann::json doc = {{"counts", {1, 2.0, element}}};
    JsonReader r(doc, "doc");
    std::vector<int64_t> counts = {9};
    r.Read("counts", &counts);
    EXPECT_EQ(r.status().field(), "counts[2]") << why;
    EXPECT_NE(r.status().message().find(why), std::string::npos) << r.status().message();
    EXPECT_EQ(counts, std::vector<int64_t>{9});  // untouched
  }
  const nlohmann::json doc = {{"counts", {1, 2.0, -3}}};
  JsonReader r(doc, "doc");
  std::vector<int64_t> counts;
  r.Read("counts", &counts);
  ASSERT_TRUE(r.ok()) << r.status().message();
  EXPECT_EQ(counts, (std::vector<int64_t>{1, 2, -3}));
}

TEST(JsonReader, RefusesAVectorOfTheWrongLengthAndANonObjectMember) {
  {
    JsonReader r(kDoc, "doc");
    Eigen::Vector3d v;
    r.Object("parameters").Read("short", &v);
    EXPECT_EQ(r.status().field(), "parameters.short");
    EXPECT_NE(r.status().message().find("expected 3 numbers, found 2"), std::string::npos);
  }
  {
    JsonReader r(kDoc, "doc");
    double x = 0;
    r.Object("parameters").Object("count").Read("x", &x);
    EXPECT_EQ(r.status().field(), "parameters.count");
    EXPECT_NE(r.status().message().find("expected an object, found a number"), std::string::npos);
  }
}

TEST(JsonReader, OptionalMembersAreNulloptWhenAbsentOrNull) {
  JsonReader r(kDoc, "doc");
  std::optional<double> absent = 1.0, null_member = 1.0;
  std::optional<int> count;
  r.Object("parameters").Read("absent", &absent);
  r.Read("nothing", &null_member);
  r.Object("parameters").Read("count", &count);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(absent.has_value());
  EXPECT_FALSE(null_member.has_value());
  EXPECT_EQ(count, 3);
  EXPECT_FALSE(r.OptionalObject("nothing").has_value());
  EXPECT_FALSE(r.Has("nothing"));
}

TEST(JsonReader, AnAbsentExtensionKeepsItsDefaultAndAPresentOneIsReadAndChecked) {
  JsonReader r(kDoc, "doc");
  int absent = 42;
  int count = 0;
  std::vector<Sensor> none = {{"default", 1}};
  r.Object("parameters").ReadExtension("added_later", &absent);
  r.Object("parameters").ReadExtension("count", &count);
  r.Object("parameters").ReadArrayExtension("also_later", &none, [](const JsonReader&, Sensor*) {});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(absent, 42);
  EXPECT_EQ(count, 3);
  EXPECT_EQ(none.size(), 1u);
  bool wrong = false;
  r.Object("parameters").ReadExtension("count", &wrong);
  EXPECT_EQ(r.status().field(), "parameters.count") << "present but of the wrong type";
}

TEST(JsonReader, NumWritesUndefinedNumbersAsNullSoTheyReadBackAsNaN) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const json j = {{"x", Num(nan)},
                  {"y", Num(std::numeric_limits<double>::infinity())},
                  {"v", Nums(Eigen::Vector3d(1, nan, 3))},
                  {"m", Rows(Eigen::Matrix3d::Identity())}};
  EXPECT_TRUE(j["x"].is_null());
  EXPECT_TRUE(j["y"].is_null());
  EXPECT_TRUE(j["v"][1].is_null());
  const json reparsed = json::parse(j.dump());
  EXPECT_EQ(reparsed, j) << "what is written equals what is stored";
  JsonReader r(reparsed, "doc");
  double x = 0;
  Eigen::Vector3d v;
  Eigen::Matrix3d m;
  r.Read("x", &x);
  r.Read("v", &v);
  r.Read("m", &m);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(std::isnan(x));
  EXPECT_TRUE(std::isnan(v(1)));
  EXPECT_EQ(m, Eigen::Matrix3d::Identity());
}

json Usable() {
  return {{"method", "pca"},
          {"model", "y = s^T u + b"},
          {"verdict",
           {{"status", "rejected"},
            {"reasons", {"too uncertain"}},
            {"limits", {{"max_scale_std", 0.01}, {"scale_range", nullptr}}}}},
          {"warnings", {"one"}}};
}

TEST(Envelope, ADocumentWithoutASchemaVersionIsVersionOneAndRoundTrips) {
  const json doc = Usable();
  JsonReader r(doc, "pca result");
  Envelope e;
  ReadEnvelope(r, "pca", 1, &e);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(e.schema_version, 1);
  EXPECT_TRUE(e.usable);
  ASSERT_TRUE(e.verdict.has_value());
  EXPECT_EQ(e.verdict->status, GateVerdict::kRejected);
  EXPECT_EQ(e.verdict->limits.at("max_scale_std"), 0.01);
  EXPECT_FALSE(e.verdict->limits.at("scale_range").has_value());
  json written = json::object();
  WriteEnvelope(e, 1, &written);
  json expected = doc;
  expected["schema_version"] = 1;
  EXPECT_EQ(written, expected);
}

TEST(Envelope, ANewerSchemaVersionIsRefusedNamingBoth) {
  json doc = Usable();
  doc["schema_version"] = 3;
  JsonReader r(doc, "pca result");
  Envelope e;
  ReadEnvelope(r, "pca", 2, &e);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().field(), "schema_version");
  EXPECT_NE(r.status().message().find("version 3 is newer than this calibd reads (up to 2)"),
            std::string::npos)
      << r.status().message();
}

TEST(Envelope, AnotherMethodsResultIsRefused) {
  const json doc = Usable();
  JsonReader r(doc, "imu result");
  Envelope e;
  ReadEnvelope(r, "imu", 1, &e);
  EXPECT_EQ(r.status().field(), "method");
  EXPECT_NE(r.status().message().find("expected \"imu\", found \"pca\""), std::string::npos);
}

TEST(Envelope, PartialDiagnosticsNeedNoModelAndSayUsableFalse) {
  const json doc = {{"method", "imu"}, {"usable", false}, {"warnings", json::array()}};
  JsonReader r(doc, "imu result");
  Envelope e;
  ReadEnvelope(r, "imu", 1, &e);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(e.usable);
  json written = json::object();
  WriteEnvelope(e, 1, &written);
  EXPECT_EQ(written["usable"], false);
  EXPECT_FALSE(written.contains("model"));
  // A usable result without a model is refused.
  const json no_model = {{"method", "imu"}, {"warnings", json::array()}};
  JsonReader r2(no_model, "imu result");
  ReadEnvelope(r2, "imu", 1, &e);
  EXPECT_EQ(r2.status().field(), "model");
}

TEST(Envelope, AVerdictWithAnUnknownStatusIsRefused) {
  json doc = Usable();
  doc["verdict"]["status"] = "maybe";
  JsonReader r(doc, "pca result");
  Envelope e;
  ReadEnvelope(r, "pca", 1, &e);
  EXPECT_EQ(r.status().field(), "verdict.status");
}

TEST(Triad, ImuTriadsRoundTripAndNameAMissingMatrix) {
  ImuTriads t;
  t.name = "3";
  t.accelerometer.scale = Eigen::Vector3d(1.01, 0.99, 1.0);
  t.gyroscope.misalignment(0, 1) = 0.002;
  ImuTriadsStd s;
  s.name = "3";
  s.accelerometer.bias_std = Eigen::Vector3d(1e-3, 2e-3, 3e-3);
  json doc = {{"imus", json::array({json::object()})}, {"stds", json::array({json::object()})}};
  WriteImuTriads(t, &doc["imus"][0]);
  WriteImuTriads(s, &doc["stds"][0]);
  const json stored = json::parse(doc.dump());
  JsonReader r(stored, "imu result");
  std::vector<ImuTriads> imus;
  std::vector<ImuTriadsStd> stds;
  r.ReadArray("imus", &imus, [](const JsonReader& e, ImuTriads* out) { ReadImuTriads(e, out); });
  r.ReadArray("stds", &stds, [](const JsonReader& e, ImuTriadsStd* out) { ReadImuTriads(e, out); });
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(imus.size(), 1u);
  EXPECT_EQ(imus[0].accelerometer.scale, t.accelerometer.scale);
  EXPECT_EQ(imus[0].gyroscope.misalignment, t.gyroscope.misalignment);
  EXPECT_EQ(stds[0].accelerometer.bias_std, s.accelerometer.bias_std);
  EXPECT_TRUE(std::isnan(stds[0].gyroscope.scale_std(0))) << "undefined stays undefined";

  json broken = stored;
  broken["imus"][0]["gyroscope"].erase("matrix");
  JsonReader r2(broken, "imu result");
  r2.ReadArray("imus", &imus, [](const JsonReader& e, ImuTriads* out) { ReadImuTriads(e, out); });
  EXPECT_EQ(r2.status().field(), "imus[0].gyroscope.matrix");
}

}  // namespace
}  // namespace calibd::results
