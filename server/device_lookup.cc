#include "server/device_lookup.h"

#include <unicode/uchar.h>

#include <algorithm>
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

namespace {

// The case variants of a typed prefix (ASCII letters either case, every other byte itself), as
// ranges of serials in byte order.
class CaseVariants {
 public:
  explicit CaseVariants(const std::string& typed) : typed_(typed) {}

  // The smallest variant: every letter upper case ('A' < 'a').
  std::string First() const { return Completion(std::string(), 0); }

  bool Matches(const std::string& serial) const {
    if (serial.size() < typed_.size()) return false;
    for (size_t i = 0; i < typed_.size(); ++i) {
      if (!IsOption(i, serial[i])) return false;
    }
    return true;
  }

  // The smallest variant greater than `serial`, a serial that does not match (no variant is its
  // prefix); false when there is none. No serial between the two matches.
  bool NextAfter(const std::string& serial, std::string* out) const {
    size_t m = 0;  // the longest prefix of `serial` that is a variant's prefix
    while (m < typed_.size() && m < serial.size() && IsOption(m, serial[m])) ++m;
    for (size_t i = m;; --i) {
      if (i == serial.size()) {  // `serial` is a proper prefix of variants
        *out = Completion(serial.substr(0, i), i);
        return true;
      }
      const unsigned char c = static_cast<unsigned char>(serial[i]);
      const unsigned char lo = Lower(i), up = Upper(i);
      const unsigned char smallest = std::min(lo, up), largest = std::max(lo, up);
      const int bigger = smallest > c ? smallest : (largest > c ? largest : -1);
      if (bigger >= 0) {
        *out = Completion(serial.substr(0, i) + static_cast<char>(bigger), i + 1);
        return true;
      }
      if (i == 0) return false;
    }
  }

 private:
  unsigned char Upper(size_t i) const {
    const unsigned char c = static_cast<unsigned char>(typed_[i]);
    return c >= 'a' && c <= 'z' ? c - 32 : c;
  }
  unsigned char Lower(size_t i) const {
    const unsigned char c = static_cast<unsigned char>(typed_[i]);
    return c >= 'A' && c <= 'Z' ? c + 32 : c;
  }
  bool IsOption(size_t i, char c) const {
    const unsigned char u = static_cast<unsigned char>(c);
    return u == Upper(i) || u == Lower(i);
  }
  // `head` followed by the smallest options from position `from` on.
  std::string Completion(std::string head, size_t from) const {
    for (size_t i = from; i < typed_.size(); ++i) head += static_cast<char>(Upper(i));
    return head;
  }

  const std::string& typed_;
};

}  // namespace

Status MatchStoredDevices(storage::Store* store, const std::string& typed, size_t limit,
                          size_t max_reads, web::DeviceMatch* out, bool* complete) {
  *out = web::DeviceMatch();
  *complete = true;
  if (typed.empty()) return Status::Ok();
  std::vector<storage::DeviceInfo> page;
  storage::DeviceFilter filter;
  filter.serial = typed;
  filter.limit = 1;
  Status s = store->ListDevices(filter, &page);
  if (!s.ok()) return s;
  if (!page.empty()) {
    out->exact = true;
    out->devices = {typed};
    return Status::Ok();
  }
  const CaseVariants variants(typed);
  filter = storage::DeviceFilter();
  filter.after = variants.First();
  filter.from = true;
  size_t reads = 0;
  for (;;) {
    if (reads >= max_reads) {
      *complete = false;
      return Status::Ok();
    }
    filter.limit = static_cast<int>(std::min<size_t>(max_reads - reads, 64));
    s = store->ListDevices(filter, &page);
    if (!s.ok()) return s;
    reads += page.size();
    std::string next;  // where the next variant's range starts, after a serial that did not match
    bool jump = false;
    for (const auto& d : page) {
      if (variants.Matches(d.serial)) {
        if (out->devices.size() < limit) {
          out->devices.push_back(d.serial);
        } else {
          ++out->more;
        }
        continue;
      }
      if (!variants.NextAfter(d.serial, &next)) return Status::Ok();  // past every variant
      jump = true;
      break;  // what the page holds before `next` cannot match: read on from `next`
    }
    if (static_cast<int>(page.size()) < filter.limit && !jump) return Status::Ok();
    filter.after = jump ? next : page.back().serial;
    filter.from = jump;
  }
}

}  // namespace calibd::server
