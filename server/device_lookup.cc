#include "server/device_lookup.h"

#include <unicode/uchar.h>

#include <vector>

#include "base/utf8.h"

namespace calibd::server {

namespace {

constexpr size_t kMaxSerialBytes = 128;

Status SerialError(const std::string& message) {
  return Status::InvalidInput("'device' " + message).WithField("device");
}

// Why `cp` may not be in a serial ("" = it may), `edge` when it is the first or last character.
std::string RefusedBecause(char32_t cp, bool edge) {
  const auto c = static_cast<UChar32>(cp);
  if (cp == '/') return "it separates the parts of URLs";
  if (u_charType(c) == U_CONTROL_CHAR) return "a control character";
  if (u_hasBinaryProperty(c, UCHAR_BIDI_CONTROL)) {
    return "a bidi control: it reorders how the serial is shown";
  }
  if (u_hasBinaryProperty(c, UCHAR_DEFAULT_IGNORABLE_CODE_POINT) ||
      u_charType(c) == U_FORMAT_CHAR) {
    return "an invisible character";
  }
  if (u_charType(c) == U_LINE_SEPARATOR || u_charType(c) == U_PARAGRAPH_SEPARATOR) {
    return "a line break";
  }
  if (u_isUWhiteSpace(c)) {
    if (edge) return "white space at the start or end";
    if (cp != ' ') return "white space that looks like U+0020 SPACE";
  }
  return "";
}

// The code points of valid UTF-8 `s`.
std::vector<char32_t> CodePoints(const std::string& s) {
  std::vector<char32_t> out;
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8SequenceLength(s, i);
    if (n == 0) {
      out.push_back(0xFFFD);
      ++i;
      continue;
    }
    out.push_back(DecodeUtf8(s, i, n));
    i += n;
  }
  return out;
}

// "(character 1: U+0421 CYRILLIC CAPITAL LETTER ES, not U+0043 LATIN CAPITAL LETTER C)".
std::string FirstDifference(const std::string& asked, const std::string& stored) {
  const std::vector<char32_t> a = CodePoints(asked), b = CodePoints(stored);
  size_t i = 0;
  while (i < a.size() && i < b.size() && a[i] == b[i]) ++i;
  const std::string at = "character " + std::to_string(i + 1) + ": ";
  if (i < a.size() && i < b.size()) {
    return "(" + at + DescribeCodePoint(a[i]) + ", not " + DescribeCodePoint(b[i]) + ")";
  }
  if (i < a.size()) return "(" + at + "an extra " + DescribeCodePoint(a[i]) + ")";
  return "(" + at + DescribeCodePoint(b[i]) + " missing)";
}

}  // namespace

Status NormalizeSerial(std::string_view raw, std::string* out) {
  if (raw.empty()) return SerialError("must have 1 to 128 bytes (the serial number)");
  for (size_t i = 0; i < raw.size();) {
    const size_t n = Utf8SequenceLength(raw, i);
    if (n == 0) return SerialError("is not UTF-8 text (byte " + std::to_string(i + 1) + ")");
    i += n;
  }
  std::string nfc = ToNfc(raw);
  if (nfc.size() > kMaxSerialBytes) {
    return SerialError("must have 1 to 128 bytes, not " + std::to_string(nfc.size()));
  }
  const std::vector<char32_t> cps = CodePoints(nfc);
  for (size_t k = 0; k < cps.size(); ++k) {
    const std::string why = RefusedBecause(cps[k], k == 0 || k + 1 == cps.size());
    if (!why.empty()) {
      return SerialError("has " + DescribeCodePoint(cps[k]) + " at character " +
                         std::to_string(k + 1) + " of " + std::to_string(cps.size()) + ": " + why +
                         "; serials that look the same must be the same device, so it is refused "
                         "(remove it)");
    }
  }
  *out = std::move(nfc);
  return Status::Ok();
}

std::string SimilarDeviceMessage(storage::Store* store, const std::string& serial) {
  const std::string key = LookAlikeKey(serial);
  storage::DeviceFilter filter;
  filter.limit = 1000;
  std::vector<storage::DeviceInfo> page;
  std::string near;
  bool found = false;
  for (;;) {
    if (!store->ListDevices(filter, &page).ok()) return "";
    for (const auto& d : page) {
      if (d.serial == serial) return "";  // it exists (the caller's lookup found another lack)
      if (!found && LookAlikeKey(d.serial) == key) {
        near = d.serial;
        found = true;
      }
    }
    if (static_cast<int>(page.size()) < filter.limit) break;
    filter.after = page.back().serial;
  }
  if (!found) return "";
  return "no device '" + serial + "'; did you mean '" + near + "'? They look alike " +
         FirstDifference(serial, near) + ".";
}

}  // namespace calibd::server
