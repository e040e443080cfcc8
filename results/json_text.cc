// JSON text to a document, with the position of a syntax error (results/json_text.h).
#include "results/json_text.h"

#include <algorithm>
#include <cstdint>

namespace calibd::results {

using nlohmann::json;

namespace {

// 1-based line and column of byte `offset` in `text`.
void LineColumn(std::string_view text, size_t offset, int64_t* line, int64_t* column) {
  *line = 1;
  *column = 1;
  offset = std::min(offset, text.size());
  for (size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++*line;
      *column = 1;
    } else {
      ++*column;
    }
  }
}

}  // namespace

Status ParseJsonText(std::string_view text, const std::string& what, json* out) {
  bool too_deep = false;
  // The callback sees every event with its depth; discarding is not enough (the parser would
  // still descend), so a too-deep document is stopped by throwing out of the callback.
  struct TooDeep {};
  try {
    *out = json::parse(
        text.begin(), text.end(),
        [&](int depth, json::parse_event_t event, json&) {
          if (depth > kMaxJsonDepth && (event == json::parse_event_t::object_start ||
                                        event == json::parse_event_t::array_start)) {
            too_deep = true;
            throw TooDeep{};
          }
          return true;
        },
        /*allow_exceptions=*/true, /*ignore_comments=*/false);
  } catch (const TooDeep&) {
  } catch (const json::parse_error& e) {
    int64_t line, column;
    LineColumn(text, e.byte > 0 ? e.byte - 1 : 0, &line, &column);
    std::string msg = e.what();
    // nlohmann's message is "[json.exception.parse_error.101] parse error at line 1, column 2:
    // syntax error while parsing value - ..." : keep the part after the location.
    const size_t colon = msg.find(": ");
    if (colon != std::string::npos) msg = msg.substr(colon + 2);
    return Status::InvalidInput("invalid JSON: " + msg).WithFile(what).WithLocation(line, column);
  } catch (const json::exception&) {
    return Status::InvalidInput("invalid JSON").WithFile(what);
  }
  if (too_deep) {
    return Status::InvalidInput("JSON nested deeper than " + std::to_string(kMaxJsonDepth) +
                                " levels")
        .WithFile(what);
  }
  return Status::Ok();
}

}  // namespace calibd::results
