// libFuzzer target: the whole offline/worker calibration path, Calibrate(bytes, name, config),
// on a fuzzed config and a fuzzed CSV (bounded by -max_len, e.g. 4 kB).
//
// Input: "CONFIG JSON\n%%\nCSV bytes". Without the "\n%%\n" separator the whole input is the CSV
// and the config is {"method": "pca"}. A config that is not valid JSON is replaced by
// {"method": "pca"} too, so the fuzzer spends its time in the methods, not in the JSON parser.
// Invariants: no crash, exception or sanitizer report; the outcome is OK, kInvalidInput or
// kNotDeterminable (never kInternal or another code), with a message; an OK result is a JSON
// object that dumps, and a second run gives the same result (SPEC §6: results are deterministic).
// Array configs run at most 8 solver iterations (BoundIterations). The config may not name a
// file: `accelerometer_calibration` as a string would read a path
// offline, which the fuzzer must not do, so such configs are skipped.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "server/config.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using nlohmann::json;

[[noreturn]] void Fail(const char* what, const Status& s) {
  std::fprintf(stderr, "fuzz_calibrate invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (!ok) Fail(what, s);
}

bool NamesAFile(const json& config) {
  if (!config.is_object()) return false;
  auto it = config.find("accelerometer_calibration");
  return it != config.end() && it->is_string();
}

// The array solvers' iteration count multiplies the cost of an input (500 BCD sweeps by default)
// without reaching new code after the first few, and the instrumented build runs ~100x slower
// than Release: an absent or larger integer max_iterations becomes kMaxIterations. Anything
// else (a string, a fraction, a negative number) is left for the validation to refuse.
constexpr int kMaxIterations = 8;
void BoundIterations(json* config) {
  if (!config->is_object() || config->value("method", json()) != "array") return;
  auto it = config->find("max_iterations");
  if (it == config->end() || (it->is_number_integer() && *it > kMaxIterations)) {
    (*config)["max_iterations"] = kMaxIterations;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  std::string_view config_text, csv = input;
  if (const size_t sep = input.find("\n%%\n"); sep != std::string_view::npos) {
    config_text = input.substr(0, sep);
    csv = input.substr(sep + 4);
  }
  json config = {{"method", "pca"}};
  if (!config_text.empty()) {
    json parsed;
    if (calibd::server::ParseJsonText(config_text, "config.json", &parsed).ok()) {
      config = std::move(parsed);
    }
  }
  if (NamesAFile(config)) return -1;  // not added to the corpus
  BoundIterations(&config);

  json result;
  Status s = calibd::server::Calibrate(csv, "fuzz.csv", config, &result);
  if (!s.ok()) {
    Check(s.code() == StatusCode::kInvalidInput || s.code() == StatusCode::kNotDeterminable ||
              s.code() == StatusCode::kTooLarge,
          "unexpected error code", s);
    Check(!s.message().empty(), "error without a message", s);
    return 0;
  }
  Check(result.is_object(), "result is not an object");
  const std::string first = result.dump(-1, ' ', false, json::error_handler_t::strict);
  json again;
  s = calibd::server::Calibrate(csv, "fuzz.csv", config, &again);
  Check(s.ok(), "second run failed", s);
  if (again.dump(-1, ' ', false, json::error_handler_t::strict) != first) {
    std::fprintf(stderr, "first:  %s\nsecond: %s\n", first.c_str(), again.dump().c_str());
    Fail("the same recording and config gave two different results", s);
  }
  return 0;
}
