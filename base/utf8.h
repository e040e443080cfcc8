// UTF-8 validation (RFC 3629: no overlong forms, no surrogates, nothing past U+10FFFF), for
// every layer: the recording parser refuses invalid text, the pages and JSON replace it.
#ifndef CALIBD_BASE_UTF8_H_
#define CALIBD_BASE_UTF8_H_

#include <cstddef>
#include <string>
#include <string_view>

namespace calibd {

// Length (1-4) of the valid UTF-8 sequence starting at s[i] (i < s.size()), or 0 when it is
// invalid or truncated.
size_t Utf8SequenceLength(std::string_view s, size_t i);

// True when all of `s` is valid UTF-8.
bool IsValidUtf8(std::string_view s);

// `s` with every invalid byte replaced by U+FFFD (used before handing strings to nlohmann::json).
std::string SanitizeUtf8(std::string_view s);

}  // namespace calibd

#endif  // CALIBD_BASE_UTF8_H_
