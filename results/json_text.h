// JSON text to a document: every config, query value and stored result calibd reads goes through
// ParseJsonText, which bounds the nesting and names the line and column of a syntax error.
#ifndef CALIBD_RESULTS_JSON_TEXT_H_
#define CALIBD_RESULTS_JSON_TEXT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "base/status.h"

namespace calibd::results {

// Nesting deeper than this in any JSON we accept is an error (guards the stack and memory).
inline constexpr int kMaxJsonDepth = 64;

// Parses JSON text. Errors are kInvalidInput naming `what` (e.g. "config.json") with the 1-based
// line and column of the fault. Rejects nesting deeper than kMaxJsonDepth.
Status ParseJsonText(std::string_view text, const std::string& what, nlohmann::json* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_JSON_TEXT_H_
