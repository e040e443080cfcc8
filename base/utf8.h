// UTF-8 validation (RFC 3629: no overlong forms, no surrogates, nothing past U+10FFFF), for
// every layer: the recording parser refuses invalid text, the pages and JSON replace it. And the
// Unicode operations serials need (normalization, names, look-alike keys), from ICU.
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

// ---- Unicode text that looks alike (ICU) ----

// The code point of the valid UTF-8 sequence of length n at s[i] (Utf8SequenceLength).
char32_t DecodeUtf8(std::string_view s, size_t i, size_t n);

// The NFC form (Unicode normalization form C, composed) of `s`; invalid UTF-8 is replaced by
// U+FFFD first. "CAFE\u0301" -> "CAF\u00c9".
std::string ToNfc(std::string_view s);

// "U+200B ZERO WIDTH SPACE": the code point and its Unicode name, for messages.
std::string DescribeCodePoint(char32_t cp);

// A key under which strings a reader cannot tell apart are equal: `s` case-folded, without its
// default-ignorable code points (zero-width characters, byte-order mark, bidi controls) and its
// leading and trailing white space, mapped to its Unicode TR39 confusable skeleton (ICU
// uspoof_getSkeleton; Cyrillic "\u0410" and Latin "A" both give "a"). Not for display.
std::string LookAlikeKey(std::string_view s);

}  // namespace calibd

#endif  // CALIBD_BASE_UTF8_H_
