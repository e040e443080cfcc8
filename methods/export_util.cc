// Shared pieces of the exports (methods/export_util.h).
#include "methods/export_util.h"

#include <cctype>
#include <cstdio>
#include <sstream>

#include "base/sha256.h"

namespace calibd::server {

std::string CsvNumber(const json& v) {
  if (!v.is_number()) return "";  // null: undefined value, an empty CSV cell
  char buf[40];
  // + 0.0: a negative zero (from a product or a rotation) is written as 0, not "-0".
  std::snprintf(buf, sizeof buf, "%.17g", v.get<double>() + 0.0);
  return buf;
}

// CSV field: quoted when it holds a comma, quote or line break. A text starting with = + - @,
// tab or CR would be run as a formula by a spreadsheet (OWASP "CSV injection"): it gets a leading
// apostrophe, which spreadsheets take as "text" and do not show.
std::string CsvField(const std::string& text) {
  const bool formula = !text.empty() && std::string("=+-@\t\r").find(text[0]) != std::string::npos;
  const std::string s = formula ? "'" + text : text;
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

// For a // comment: printable ASCII only.
std::string CommentSafe(const std::string& s) {
  std::string out;
  for (unsigned char c : s) out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  return out;
}

std::string CString(const std::string& s) {
  std::string out = "\"";
  for (unsigned char c : s) {
    if (c == '"' || c == '\\' || c == '?') {  // '?': no trigraph (C99) can form
      out += '\\';
      out += static_cast<char>(c);
    } else if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\%03o", c);
      out += buf;
    }
  }
  return out + "\"";
}

std::vector<std::string> AxisNames(size_t d) {
  static const char* xyz[] = {"x", "y", "z"};
  std::vector<std::string> names;
  for (size_t k = 0; k < d; ++k) names.push_back(d <= 3 ? xyz[k] : std::to_string(k + 1));
  return names;
}

const json& JsonAt(const json& obj, const char* key) {
  static const json kNull;
  if (!obj.is_object()) return kNull;
  auto it = obj.find(key);
  return it == obj.end() ? kNull : *it;
}

// For a /* */ comment of the C header: printable ASCII, and no "*/" or "/*" (a serial such as
// "x*/ int y; /*" must not end the comment or open another one).
std::string CComment(const std::string& s) {
  std::string out;
  for (char c : CommentSafe(s)) {
    if (!out.empty() && ((out.back() == '*' && c == '/') || (out.back() == '/' && c == '*'))) {
      out += ' ';
    }
    out += c;
  }
  return out;
}

// The identifier stem of a serial or method: letters and digits kept (upper case), every other
// byte '_'. Two serials that differ only in case or punctuation get the same stem; including both
// headers is then a compile error (redefinition), never a silent mix-up.
std::string IdentifierStem(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (c >= 'a' && c <= 'z') {
      out += static_cast<char>(c - 'a' + 'A');
    } else if ((c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')) {
      out += static_cast<char>(c);
    } else {
      out += '_';
    }
  }
  return out.empty() ? "_" : out;
}

std::string DeviceStem(const std::string& serial) {
  std::string stem = IdentifierStem(serial);
  for (unsigned char c : serial) {
    if (c >= 0x80) {
      std::string hash = Sha256Hex(serial).substr(0, 8);
      for (char& h : hash) h = static_cast<char>(std::toupper(static_cast<unsigned char>(h)));
      return stem + "_" + hash;
    }
  }
  return stem;
}

std::string LowerCase(std::string s) {
  for (char& c : s) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return s;
}

// A C double literal (full precision); the caller has checked that v is a finite number.
Status UnreadableStoredResult(const Status& read) {
  return Status::Conflict("the stored " + read.message());
}

std::string CDouble(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v + 0.0);  // no "-0.0"
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

std::string MeasuredRate(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

// Reads `n` numbers of a JSON array into *out; false when the shape is wrong or any is null.
bool Numbers(const json& v, size_t n, std::vector<double>* out) {
  out->clear();
  if (!v.is_array() || v.size() != n) return false;
  for (const json& x : v) {
    if (!x.is_number()) return false;
    out->push_back(x.get<double>());
  }
  return true;
}

// Per-entry standard deviations: the array when every entry is defined, else a comment naming
// the entries whose σ is undefined (never a made-up 0).
void StdArray1(HeaderWriter* w, const std::string& name, const json& items, const char* key,
               const std::vector<std::string>& names, const std::string& comment) {
  std::vector<double> values;
  std::string undefined;
  for (size_t i = 0; i < names.size(); ++i) {
    const json& v = items.is_array() && i < items.size() ? JsonAt(items[i], key) : json();
    if (v.is_number()) {
      values.push_back(v.get<double>());
    } else {
      undefined += (undefined.empty() ? "" : ", ") + names[i];
    }
  }
  if (undefined.empty()) {
    w->Array1(name, values, comment);
  } else {
    w->out() << "/* " << w->macro() << name << " is not written: " << CComment(key)
             << " is undefined for " << CComment(undefined) << " (see format=json). */\n";
  }
}

Status WriteCHeader(
    const json& result, const ExportContext& context, const std::string& method,
    const char* model_comment,
    const std::function<Status(const json& params, const json& unc, HeaderWriter* w)>& body_writer,
    std::string* out) {
  HeaderWriter body(context, method);
  Status s = body_writer(JsonAt(result, "parameters"), JsonAt(result, "uncertainty"), &body);
  if (!s.ok()) return s;
  const std::string guard = body.macro() + "JOB_" + std::to_string(context.job_id) + "_H_";
  std::ostringstream h;
  h << "/* Generated by calibd: " << CComment(method) << " calibration of device '"
    << CComment(context.device) << "', job " << context.job_id << ", finished "
    << CComment(context.finished_at) << ".\n"
    << " * Fetch again from /api/v1/devices/{serial}/calibration?method=" << CComment(method)
    << "&format=h; do not edit.\n"
    << " * Valid C99 and C++; every name starts with " << body.macro() << " or " << body.func()
    << ",\n"
    << " * so headers of several devices and methods can be included in one program.\n"
    << " *\n"
    << model_comment << " */\n"
    << "#ifndef " << guard << "\n#define " << guard << "\n\n";
  HeaderWriter head(context, method);
  head.Define("JOB_ID", std::to_string(context.job_id) + "LL", "");
  head.Define("DEVICE", CString(context.device), "");
  head.Define("FINISHED_AT", CString(context.finished_at), "UTC");
  // Firmware builds can refuse a file that is not a device's served calibration:
  // #if !PREFIX_ACCEPTED / #error ... #endif.
  head.Define("ACCEPTED", IsAcceptedExport(context) ? "1" : "0",
              IsAcceptedExport(context)
                  ? "accepted: served as the device's calibration"
                  : "NOT FOR USE: this result was " + context.state +
                        (context.state == "rejected" ? " by the acceptance gate" : " by a person") +
                        "; it is never served as the device's calibration");
  h << head.out().str() << body.out().str() << "\n#endif /* " << guard << " */\n";
  *out = h.str();
  return Status::Ok();
}

}  // namespace calibd::server
