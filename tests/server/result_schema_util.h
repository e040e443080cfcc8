// Helpers of the result-schema tests (tests/server/<method>_result_schema_test.cc): a result cut
// down to the keys SPEC names, its stored form, and the typed round trip.
#ifndef CALIBD_TESTS_SERVER_RESULT_SCHEMA_UTIL_H_
#define CALIBD_TESTS_SERVER_RESULT_SCHEMA_UTIL_H_

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"

namespace calibd::server::testing {

// `j` with every member removed, recursively, that is not on one of `spec_paths` nor leads to one
// (paths like "parameters.channels[].name": "[]" stands for every element of an array).
inline nlohmann::json SpecOnly(const nlohmann::json& j, const std::vector<std::string>& spec_paths,
                               const std::string& path = "") {
  if (j.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const nlohmann::json& e : j) out.push_back(SpecOnly(e, spec_paths, path + "[]"));
    return out;
  }
  if (!j.is_object()) return j;
  auto on_the_way = [&](const std::string& p) {
    for (const std::string& spec : spec_paths) {
      if (spec == p || spec.rfind(p + ".", 0) == 0 || spec.rfind(p + "[]", 0) == 0) return true;
    }
    return false;
  };
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [key, value] : j.items()) {
    const std::string p = path.empty() ? key : path + "." + key;
    if (on_the_way(p)) out[key] = SpecOnly(value, spec_paths, p);
  }
  return out;
}

// The stored form of a result: its JSON text parsed back (NaN as null, as the store keeps it).
inline nlohmann::json Stored(const nlohmann::json& result) {
  return nlohmann::json::parse(result.dump());
}

// `stored` reads into the typed result `Typed` (results::FromJson) and writes back identically.
template <typename Typed>
void ExpectTypedRoundTrip(const nlohmann::json& stored) {
  Typed typed;
  const Status s = FromJson(stored, &typed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(ToJson(typed), stored)
      << "ToJson: " << ToJson(typed).dump() << "\nstored: " << stored.dump();
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_SERVER_RESULT_SCHEMA_UTIL_H_
