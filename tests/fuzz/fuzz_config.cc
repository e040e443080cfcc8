// libFuzzer target: the config parsers (server/config.h) on arbitrary text.
//
// The input is used twice: (1) as JSON text for ParseJsonText, and, when that succeeds, for
// ValidateConfig; (2) split at '&' and '=' into query parameters (percent-decoding is httplib's
// job, so the raw bytes are the values) for ConfigFromQuery, then ValidateConfig.
// Invariants: no crash, no exception escapes (libFuzzer reports an uncaught one as a crash), no
// sanitizer report; a JSON error has line >= 1, column >= 1 and a message; an accepted document
// is at most kMaxJsonDepth deep and dumps without throwing; every error of ValidateConfig and
// ConfigFromQuery is kInvalidInput with a message.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "methods/method.h"
#include "methods/registry.h"
#include "server/config.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::CommonConfig;
using nlohmann::json;

[[noreturn]] void Fail(const char* what, const Status& s) {
  std::fprintf(stderr, "fuzz_config invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (!ok) Fail(what, s);
}

int Depth(const json& j) {
  int deepest = 0;
  if (j.is_structured()) {
    for (const auto& child : j) deepest = std::max(deepest, Depth(child));
    return deepest + 1;
  }
  return 0;
}

void CheckValidate(const json& config) {
  CommonConfig common;
  Status s = calibd::server::ValidateConfig(config, &common);
  if (s.ok()) {
    // Every method of the registry is valid (pca, array, imu, noise); nothing else is.
    Check(calibd::server::FindMethod(common.method) != nullptr, "accepted an unknown method");
    Check(common.device.size() <= 128, "accepted an overlong device");
    // What the server stores for a job: must not throw, whatever the strings hold.
    (void)config.dump(-1, ' ', false, json::error_handler_t::replace);
  } else {
    Check(s.code() == StatusCode::kInvalidInput, "ValidateConfig: unexpected code", s);
    Check(!s.message().empty(), "ValidateConfig: error without a message", s);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);

  // (1) JSON text.
  json parsed;
  Status s = calibd::server::ParseJsonText(text, "config.json", &parsed);
  if (s.ok()) {
    Check(Depth(parsed) <= calibd::server::kMaxJsonDepth + 1, "accepted a too deep document");
    (void)parsed.dump();  // nlohmann only accepts valid UTF-8, so this cannot throw
    CheckValidate(parsed);
  } else {
    Check(s.code() == StatusCode::kInvalidInput, "ParseJsonText: unexpected code", s);
    Check(!s.message().empty(), "ParseJsonText: error without a message", s);
    Check(s.file() == "config.json", "ParseJsonText: error does not name the file", s);
    if (s.line() != 0 || s.column() != 0) {
      Check(s.line() >= 1 && s.column() >= 1, "ParseJsonText: bad location", s);
    }
  }

  // (2) Query parameters.
  std::multimap<std::string, std::string> params;
  size_t pos = 0;
  while (pos <= text.size()) {
    size_t amp = text.find('&', pos);
    if (amp == std::string_view::npos) amp = text.size();
    const std::string_view pair = text.substr(pos, amp - pos);
    const size_t eq = pair.find('=');
    if (eq == std::string_view::npos) {
      params.emplace(std::string(pair), std::string());
    } else {
      params.emplace(std::string(pair.substr(0, eq)), std::string(pair.substr(eq + 1)));
    }
    pos = amp + 1;
  }
  json config;
  s = calibd::server::ConfigFromQuery(params, &config);
  if (s.ok()) {
    Check(config.is_object(), "ConfigFromQuery did not make an object");
    CheckValidate(config);
  } else {
    Check(s.code() == StatusCode::kInvalidInput, "ConfigFromQuery: unexpected code", s);
    Check(!s.message().empty(), "ConfigFromQuery: error without a message", s);
  }
  return 0;
}
