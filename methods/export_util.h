// Shared pieces of the exports of every method (server/<name>_exports.cc): CSV cells, C literals
// and comments, and the C header's frame (WriteCHeader). Internal to server/.
#ifndef CALIBD_SERVER_EXPORT_UTIL_H_
#define CALIBD_SERVER_EXPORT_UTIL_H_

#include <cstddef>
#include <functional>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "base/status.h"
#include "methods/exports.h"

namespace calibd::server {

using json = nlohmann::json;

// A CSV cell of a number at full precision (%.17g; -0 as 0); "" for null (an undefined value).
std::string CsvNumber(const json& v);
// CSV field: quoted when it holds a comma, quote or line break; a text a spreadsheet would run
// as a formula (starting with = + - @, tab or CR) gets a leading apostrophe.
std::string CsvField(const std::string& s);
// For a // comment: printable ASCII only.
std::string CommentSafe(const std::string& s);
// A C string literal (escaped; no trigraph can form).
std::string CString(const std::string& s);
// "x", "y", "z" for d <= 3, else "1", "2", ...
std::vector<std::string> AxisNames(size_t d);
// Member `key` of an object; a null json when absent or not an object.
const json& JsonAt(const json& obj, const char* key);
// For a /* */ comment of the C header: printable ASCII, and no "*/" or "/*".
std::string CComment(const std::string& s);
// Letters and digits kept (upper case), every other byte '_' (identifier stems).
std::string IdentifierStem(const std::string& s);
// The identifier stem of a device serial: IdentifierStem, plus "_" and 8 hex digits of the
// serial's SHA-256 when the serial has bytes beyond ASCII, whose transliteration to '_' loses
// what tells serials apart ("Drohne-Üß-測試" and "drohne-üß-測試" would both be DROHNE________).
std::string DeviceStem(const std::string& serial);
std::string LowerCase(std::string s);
// A stored result this calibd cannot read (results::FromJson failed: written by a newer calibd, or
// damaged): 409 with the reader's message, which names the path ("... schema_version: version 2 is
// newer than this calibd reads (up to 1): upgrade calibd to read it"), not an opaque 500.
Status UnreadableStoredResult(const Status& read);
// A C double literal (full precision); v must be finite.
std::string CDouble(double v);
// A measured sample rate as written to files: 6 significant digits, the precision a rate measured
// from a log's time stamps has (100.01013117051603 -> "100.01"), always with a decimal point
// ("100.0"); v finite.
std::string MeasuredRate(double v);
// Reads `n` numbers of a JSON array into *out; false when the shape is wrong or any is null.
bool Numbers(const json& v, size_t n, std::vector<double>* out);

// Writes a C99/C++ header. Constants are `static const` (internal linkage in both languages) or
// macros, all named PREFIX_...; functions prefix_... (lower case).
class HeaderWriter {
 public:
  HeaderWriter(const ExportContext& context, const std::string& method)
      : macro_("CALIBD_" + DeviceStem(context.device) + "_" + IdentifierStem(method) + "_"),
        func_(LowerCase(macro_)) {}

  const std::string& macro() const { return macro_; }
  const std::string& func() const { return func_; }
  std::ostringstream& out() { return h_; }

  void Define(const std::string& name, const std::string& value, const std::string& comment) {
    h_ << "#define " << macro_ << name << " " << value;
    if (!comment.empty()) h_ << "  /* " << CComment(comment) << " */";
    h_ << "\n";
  }
  void Array1(const std::string& name, const std::vector<double>& v, const std::string& comment) {
    if (!comment.empty()) h_ << "/* " << CComment(comment) << " */\n";
    h_ << "static const double " << macro_ << name << "[" << v.size() << "] = {";
    for (size_t i = 0; i < v.size(); ++i) h_ << (i ? ", " : "") << CDouble(v[i]);
    h_ << "};\n";
  }
  void Array2(const std::string& name, const std::vector<std::vector<double>>& rows, size_t cols,
              const std::string& comment) {
    if (!comment.empty()) h_ << "/* " << CComment(comment) << " */\n";
    h_ << "static const double " << macro_ << name << "[" << rows.size() << "][" << cols
       << "] = {\n";
    for (const auto& row : rows) {
      h_ << "    {";
      for (size_t c = 0; c < row.size(); ++c) h_ << (c ? ", " : "") << CDouble(row[c]);
      h_ << "},\n";
    }
    h_ << "};\n";
  }
  void Names(const std::string& name, const std::vector<std::string>& names) {
    h_ << "static const char* const " << macro_ << name << "[" << names.size() << "] = {";
    for (size_t i = 0; i < names.size(); ++i) h_ << (i ? ", " : "") << CString(names[i]);
    h_ << "};\n";
  }

 private:
  std::string macro_, func_;
  std::ostringstream h_;
};

// Per-entry standard deviations: the array when every entry is defined, else a comment naming
// the entries whose σ is undefined (never a made-up 0).
void StdArray1(HeaderWriter* w, const std::string& name, const json& items, const char* key,
               const std::vector<std::string>& names, const std::string& comment);

// The C header of a result (methods/exports.h, ResultToHeader): the comment (method, device, job,
// time, `model_comment`: lines starting " * "), the include guard, JOB_ID, DEVICE, FINISHED_AT,
// then what `body_writer` writes from the result's parameters and uncertainty.
Status WriteCHeader(
    const json& result, const ExportContext& context, const std::string& method,
    const char* model_comment,
    const std::function<Status(const json& params, const json& unc, HeaderWriter* w)>& body_writer,
    std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_EXPORT_UTIL_H_
