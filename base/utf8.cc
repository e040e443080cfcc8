#include "base/utf8.h"

#include <unicode/normalizer2.h>
#include <unicode/uchar.h>
#include <unicode/unistr.h>
#include <unicode/uspoof.h>

#include <cstdint>
#include <cstdio>
#include <mutex>

namespace calibd {

size_t Utf8SequenceLength(std::string_view s, size_t i) {
  const auto b0 = static_cast<unsigned char>(s[i]);
  if (b0 < 0x80) return 1;
  size_t n;
  uint32_t cp;
  if ((b0 & 0xE0) == 0xC0) {
    n = 2;
    cp = b0 & 0x1F;
  } else if ((b0 & 0xF0) == 0xE0) {
    n = 3;
    cp = b0 & 0x0F;
  } else if ((b0 & 0xF8) == 0xF0) {
    n = 4;
    cp = b0 & 0x07;
  } else {
    return 0;
  }
  if (i + n > s.size()) return 0;
  for (size_t k = 1; k < n; ++k) {
    const auto b = static_cast<unsigned char>(s[i + k]);
    if ((b & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (b & 0x3F);
  }
  if ((n == 2 && cp < 0x80) || (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000)) return 0;
  if (cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
  return n;
}

bool IsValidUtf8(std::string_view s) {
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) return false;
    i += n;
  }
  return true;
}

std::string SanitizeUtf8(std::string_view s) {
  static constexpr char kReplacement[] = "\xEF\xBF\xBD";  // U+FFFD
  std::string out;
  out.reserve(s.size());
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) {
      out += kReplacement;
      ++i;
    } else {
      out.append(s.data() + i, n);
      i += n;
    }
  }
  return out;
}

char32_t DecodeUtf8(std::string_view s, size_t i, size_t n) {
  const auto b0 = static_cast<unsigned char>(s[i]);
  if (n == 1) return b0;
  char32_t cp = b0 & (n == 2 ? 0x1F : n == 3 ? 0x0F : 0x07);
  for (size_t k = 1; k < n; ++k) cp = (cp << 6) | (static_cast<unsigned char>(s[i + k]) & 0x3F);
  return cp;
}

// ICU's NFC normalizer, created once. Through a function-local static (not ICU's own once-flag
// alone), so that the instance's construction visibly happens before every thread's use: ICU is
// not built with ThreadSanitizer, which otherwise reports its lazy construction in one worker
// and a virtual call in another as a race. nullptr when ICU's data is missing (cannot happen with
// a linked libicu).
static const icu::Normalizer2* NfcNormalizer() {
  static const icu::Normalizer2* const nfc = [] {
    UErrorCode err = U_ZERO_ERROR;
    const icu::Normalizer2* n = icu::Normalizer2::getNFCInstance(err);
    return U_SUCCESS(err) ? n : nullptr;
  }();
  return nfc;
}

std::string ToNfc(std::string_view s) {
  UErrorCode err = U_ZERO_ERROR;
  const icu::Normalizer2* nfc = NfcNormalizer();
  const std::string valid = SanitizeUtf8(s);
  if (nfc == nullptr) return valid;
  const icu::UnicodeString in = icu::UnicodeString::fromUTF8(valid);
  if (nfc->isNormalized(in, err) && U_SUCCESS(err)) return valid;
  err = U_ZERO_ERROR;
  const icu::UnicodeString out = nfc->normalize(in, err);
  if (U_FAILURE(err)) return valid;
  std::string text;
  out.toUTF8String(text);
  return text;
}

std::string DescribeCodePoint(char32_t cp) {
  char code[16];
  std::snprintf(code, sizeof code, "U+%04X", static_cast<unsigned>(cp));
  // The name, else its correction alias, else the extended name ("<control-0009>").
  for (UCharNameChoice choice : {U_UNICODE_CHAR_NAME, U_CHAR_NAME_ALIAS, U_EXTENDED_CHAR_NAME}) {
    char name[128];
    UErrorCode err = U_ZERO_ERROR;
    const int32_t n = u_charName(static_cast<UChar32>(cp), choice, name, sizeof name, &err);
    if (U_SUCCESS(err) && n > 0 && n < static_cast<int32_t>(sizeof name)) {
      return std::string(code) + " " + std::string(name, static_cast<size_t>(n));
    }
  }
  return code;
}

std::string LookAlikeKey(std::string_view s) {
  // Strip what a reader cannot see, then fold case, then the TR39 skeleton (which works on NFD
  // and maps each confusable to its prototype).
  icu::UnicodeString text = icu::UnicodeString::fromUTF8(SanitizeUtf8(s));
  icu::UnicodeString visible;
  for (int32_t i = 0; i < text.length();) {
    const UChar32 cp = text.char32At(i);
    i += U16_LENGTH(cp);
    if (u_hasBinaryProperty(cp, UCHAR_DEFAULT_IGNORABLE_CODE_POINT) ||
        u_hasBinaryProperty(cp, UCHAR_BIDI_CONTROL)) {
      continue;
    }
    visible.append(cp);
  }
  int32_t begin = 0, end = visible.length();
  while (begin < end && u_isUWhiteSpace(visible.char32At(begin))) ++begin;
  while (end > begin && u_isUWhiteSpace(visible.char32At(end - 1))) --end;
  visible = icu::UnicodeString(visible, begin, end - begin);
  visible.foldCase();
  // One spoof checker for the process (uspoof_getSkeleton is thread-safe on a const checker).
  static USpoofChecker* checker = [] {
    UErrorCode err = U_ZERO_ERROR;
    USpoofChecker* c = uspoof_open(&err);
    return U_SUCCESS(err) ? c : nullptr;
  }();
  std::string key;
  if (checker == nullptr) {
    visible.toUTF8String(key);
    return key;
  }
  UErrorCode err = U_ZERO_ERROR;
  icu::UnicodeString skeleton;
  uspoof_getSkeletonUnicodeString(checker, 0, visible, skeleton, &err);
  (U_SUCCESS(err) ? skeleton : visible).toUTF8String(key);
  return key;
}

}  // namespace calibd
