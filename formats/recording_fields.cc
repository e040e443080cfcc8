// The recording parser's general path (formats/recording_parser.h): a line split into fields
// (RFC 4180 quotes), numbers read with std::from_chars, the header and rows checked field by
// field, and every error named with its file, line, column and header name.
#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "formats/csv_dialect.h"
#include "formats/recording.h"
#include "formats/recording_parser.h"

namespace calibd::server {

using recording_internal::Excerpt;
using recording_internal::TrimSpaces;

namespace recording_internal {

// Shortens a user string for an error message, so a hostile 1 MiB field does not echo back
// whole; control characters are shown as '?'.
std::string Excerpt(std::string_view s) {
  constexpr size_t kMax = 40;
  std::string out(s.substr(0, kMax));
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return s.size() <= kMax ? out : out + "...";
}

}  // namespace recording_internal

namespace {

constexpr char kAxes[] = {'x', 'y', 'z'};

// Spreadsheet exports (semicolon- or tab-separated, decimal commas) are refused with what to
// change; never guessed, since "1,5" in a comma-separated file is two numbers. The header line is
// checked once; rows only on their error path, so the row reader pays nothing.
constexpr const char* kCsvExportAdvice =
    "calibd reads comma-separated files; export as CSV with ',' as the separator and '.' as the "
    "decimal mark";

// The separator a line or field uses instead of ',' (';' or a tab), or 0; with its 1-based byte
// position in *at.
char ForeignSeparator(std::string_view s, size_t* at) {
  const size_t semicolon = s.find(';');
  const size_t tab = s.find('\t');
  if (semicolon == std::string_view::npos && tab == std::string_view::npos) return 0;
  const bool is_tab = tab < semicolon;
  *at = (is_tab ? tab : semicolon) + 1;
  return is_tab ? '\t' : ';';
}

std::string SeparatorName(char c) { return c == '\t' ? "a tab" : "';'"; }

// The advice for a file separated by `sep`: export it as calibd reads it, or name the config
// keys that read it as it is (formats/csv_dialect.h).
std::string SeparatorAdvice(char sep) {
  return std::string(kCsvExportAdvice) + ", or read it as it is with the config key delimiter \"" +
         (sep == '\t' ? "\\t" : ";") + "\" (and decimal \",\" if its numbers have decimal commas)";
}

// True when `text` is a number once its one ',' is read as '.' ("1,5", "-0,25e-3").
bool IsDecimalCommaNumber(std::string_view text) {
  const size_t comma = text.find(',');
  if (comma == std::string_view::npos || text.find(',', comma + 1) != std::string_view::npos) {
    return false;
  }
  std::string dotted(text);
  dotted[comma] = '.';
  double v;
  auto [ptr, ec] = std::from_chars(dotted.data(), dotted.data() + dotted.size(), v);
  return ec == std::errc() && ptr == dotted.data() + dotted.size() && comma > 0 &&
         comma + 1 < text.size();
}

// The first C0 control character or DEL in `s` (NUL, tab, CR, ...), or -1. Names and labels are
// exported into CSV files, C headers and HTML, so they must be printable.
int FirstControlCharacter(std::string_view s) {
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7f) return u;
  }
  return -1;
}

std::string ControlName(int c) {
  switch (c) {
    case 0:
      return "NUL (0x00)";
    case '\t':
      return "TAB (0x09)";
    case '\r':
      return "CR (0x0d)";
    case '\n':
      return "LF (0x0a)";
    default: {
      char text[16];
      std::snprintf(text, sizeof text, "0x%02x", c);
      return text;
    }
  }
}

}  // namespace

Status RecordingParser::Impl::Fail(std::string message, int64_t column, std::string field) {
  Status s = Status::InvalidInput(std::move(message));
  s.WithFile(file_name).WithLocation(line_no, column);
  if (!field.empty()) s.WithField(std::move(field));
  error = s;
  return s;
}

Status RecordingParser::Impl::Split(std::string_view line) {
  fields.clear();
  unquoted.clear();
  if (line.find('"') == std::string_view::npos) return SplitUnquoted(line);
  size_t pos = 0;
  while (true) {
    if (static_cast<int64_t>(fields.size()) >= limits.max_columns) {
      return Fail("more than " + std::to_string(limits.max_columns) + " columns",
                  static_cast<int64_t>(fields.size()) + 1);
    }
    const size_t start = pos;
    size_t lead = start;
    while (lead < line.size() &&
           (line[lead] == ' ' || (line[lead] == '\t' && dialect.delimiter != '\t'))) {
      ++lead;
    }
    if (lead < line.size() && line[lead] == '"') {
      std::string value;
      size_t i = lead + 1;
      bool closed = false;
      while (i < line.size()) {
        if (line[i] == '"') {
          if (i + 1 < line.size() && line[i + 1] == '"') {
            value.push_back('"');
            i += 2;
            continue;
          }
          closed = true;
          ++i;
          break;
        }
        value.push_back(line[i++]);
      }
      if (!closed) {
        return Fail("unterminated quoted field", static_cast<int64_t>(fields.size()) + 1);
      }
      while (i < line.size() &&
             (line[i] == ' ' || (line[i] == '\t' && dialect.delimiter != '\t'))) {
        ++i;
      }
      if (i < line.size() && line[i] != dialect.delimiter) {
        return Fail("unexpected text after a quoted field",
                    static_cast<int64_t>(fields.size()) + 1);
      }
      // Capacity is reserved for max_columns strings, so earlier views stay valid.
      if (unquoted.capacity() < static_cast<size_t>(limits.max_columns)) {
        unquoted.reserve(limits.max_columns);
      }
      unquoted.push_back(std::move(value));
      fields.push_back(unquoted.back());
      pos = i;
    } else {
      size_t comma = line.find(dialect.delimiter, start);
      if (comma == std::string_view::npos) comma = line.size();
      fields.push_back(TrimSpaces(line.substr(start, comma - start)));
      pos = comma;
    }
    if (pos >= line.size()) break;
    ++pos;  // skip the comma
  }
  return Status::Ok();
}

Status RecordingParser::Impl::SplitUnquoted(std::string_view line) {
  const char* p = line.data();
  const char* const end = p + line.size();
  while (true) {
    if (static_cast<int64_t>(fields.size()) >= limits.max_columns) {
      return Fail("more than " + std::to_string(limits.max_columns) + " columns",
                  static_cast<int64_t>(fields.size()) + 1);
    }
    const char* comma =
        static_cast<const char*>(memchr(p, dialect.delimiter, static_cast<size_t>(end - p)));
    const char* field_end = comma ? comma : end;
    fields.push_back(TrimSpaces(std::string_view(p, static_cast<size_t>(field_end - p))));
    if (!comma) break;
    p = comma + 1;
  }
  return Status::Ok();
}

Status RecordingParser::Impl::ParseNumber(std::string_view text, int64_t column,
                                          const std::string& name, double* value) {
  if (text.empty()) return Fail("empty cell in column '" + name + "'", column, name);
  std::string_view digits = text;
  std::string pointed;  // decimal ',': the field with its comma as a point
  if (dialect.decimal == ',' && digits.find(',') != std::string_view::npos) {
    pointed.assign(digits);
    for (char& c : pointed) c = c == ',' ? '.' : c;
    digits = pointed;
  }
  if (digits.front() == '+') digits.remove_prefix(1);
  if (ParseDecimalFast(digits, value)) return Status::Ok();
  const char* end = digits.data() + digits.size();
  auto [ptr, ec] = std::from_chars(digits.data(), end, *value);
  if (ec == std::errc::result_out_of_range) {
    return Fail("number '" + Excerpt(text) + "' in column '" + name + "' is out of range", column,
                name);
  }
  if (ec != std::errc() || ptr != end) {
    size_t at = 0;
    if (const char sep = ForeignSeparator(text, &at); sep != 0) {
      return Fail("line " + std::to_string(line_no) + " uses " + SeparatorName(sep) +
                      " as the separator ('" + Excerpt(text) + "' in column '" + name +
                      "'): " + SeparatorAdvice(sep),
                  column, name);
    }
    if (dialect.decimal == '.' && IsDecimalCommaNumber(text)) {
      std::string dotted(text);
      dotted[dotted.find(',')] = '.';
      return Fail("line " + std::to_string(line_no) + " uses ',' as the decimal mark ('" +
                      Excerpt(text) + "' in column '" + name + "'; write " + Excerpt(dotted) +
                      "): " + kCsvExportAdvice,
                  column, name);
    }
    return Fail("'" + Excerpt(text) + "' in column '" + name + "' is not a number", column, name);
  }
  if (!std::isfinite(*value)) {
    return Fail("'" + Excerpt(text) + "' in column '" + name +
                    "' is not a finite number (NaN and Inf are not allowed)",
                column, name);
  }
  return Status::Ok();
}

Status RecordingParser::Impl::RowShapeError(size_t got, size_t expected) {
  const std::string counts =
      "row has " + std::to_string(got) + " fields, the header has " + std::to_string(expected);
  const int64_t column = static_cast<int64_t>(std::min(got, expected)) + 1;
  size_t at = 0;
  if (const char sep = ForeignSeparator(line_text, &at); sep != 0) {
    return Fail("line " + std::to_string(line_no) + " uses " + SeparatorName(sep) +
                    " as the separator (first at character " + std::to_string(at) + "; " + counts +
                    "): " + SeparatorAdvice(sep),
                column);
  }
  if (got > expected) {
    return Fail(
        counts + ": if ',' is the decimal mark here (e.g. '1,5' for 1.5), " + kCsvExportAdvice,
        column);
  }
  return Fail(counts, column);
}

bool RecordingParser::Impl::ForeignHeader(std::string_view line) {
  size_t at = 0;
  const char sep = dialect.delimiter == ',' && line.find(',') == std::string_view::npos
                       ? ForeignSeparator(line, &at)
                       : 0;
  if (sep == 0) return false;
  Fail("line " + std::to_string(line_no) + " uses " + SeparatorName(sep) +
           " as the separator (first at character " + std::to_string(at) +
           "): " + SeparatorAdvice(sep),
       1);
  return true;
}

Status RecordingParser::Impl::Header() {
  const auto& f = fields;
  for (size_t i = 0; i < f.size(); ++i) {
    if (!IsValidUtf8(f[i])) {
      return Fail("column name is not valid UTF-8", static_cast<int64_t>(i) + 1);
    }
    if (const int c = FirstControlCharacter(f[i]); c >= 0) {
      return Fail("column name '" + Excerpt(f[i]) + "' contains the control character " +
                      ControlName(c) + "; names must be printable",
                  static_cast<int64_t>(i) + 1);
    }
  }
  summary.columns.assign(f.begin(), f.end());
  if (f.size() == 1 && f[0].empty()) return Fail("empty header line");
  if (!dialect.columns.empty()) {
    Status s = MapHeaderNames();
    if (!s.ok()) return s;
  }
  Status s = f[0] == "position" ? PcaHeader() : ArrayHeader();
  if (s.ok() && !dialect.IsDefault()) DescribeDialect();
  return s;
}

Status RecordingParser::Impl::MapHeaderNames() {
  std::unordered_map<std::string_view, size_t> file_column;  // header name → 0-based column
  for (size_t i = 0; i < fields.size(); ++i) file_column.emplace(fields[i], i);
  for (const auto& [calibd_name, file_name] : dialect.columns) {
    const auto first = file_column.find(file_name);
    for (size_t i = 0; first != file_column.end() && i < fields.size(); ++i) {
      if (i != first->second && fields[i] == file_name) {
        return Fail("config 'columns." + calibd_name + "' names the column '" + Excerpt(file_name) +
                        "', which the header has twice (columns " +
                        std::to_string(first->second + 1) + " and " + std::to_string(i + 1) + ")",
                    static_cast<int64_t>(i) + 1, "columns." + calibd_name);
      }
    }
  }
  std::unordered_map<std::string_view, size_t> mapped_to;  // calibd name → its file column
  for (const auto& [calibd_name, file_name] : dialect.columns) {
    const auto it = file_column.find(file_name);
    if (it == file_column.end()) {
      std::string names;
      for (size_t i = 0; i < fields.size() && i < 12; ++i) {
        names += (i ? ", '" : "'") + Excerpt(fields[i]) + "'";
      }
      if (fields.size() > 12) names += ", ...";
      return Fail("config 'columns." + calibd_name + "' names the column '" + Excerpt(file_name) +
                      "', which the header does not have (it has " + names + ")",
                  0, "columns." + calibd_name);
    }
    mapped_to.emplace(calibd_name, it->second);
  }
  // A header column already named as calibd names a mapped column: the data would be ambiguous.
  for (size_t i = 0; i < fields.size(); ++i) {
    const auto it = mapped_to.find(fields[i]);
    if (it != mapped_to.end() && it->second != i) {
      const std::string key(it->first);
      return Fail("config 'columns." + key + "' maps the column '" + Excerpt(fields[it->second]) +
                      "' (column " + std::to_string(it->second + 1) + ") to '" + key +
                      "', but the header already has a column '" + key + "' (column " +
                      std::to_string(i + 1) + "): map it to another name or leave it out",
                  static_cast<int64_t>(i) + 1, "columns." + key);
    }
  }
  for (const auto& [calibd_name, column] : mapped_to) fields[column] = calibd_name;
  return Status::Ok();
}

void RecordingParser::Impl::DescribeDialect() {
  nlohmann::json csv = dialect.ToJson();
  csv["ignored"] = ignored_columns;
  nlohmann::json description = {
      {"format", "csv"}, {"csv", csv}, {"warnings", nlohmann::json::array()}};
  if (!ignored_columns.empty()) {
    std::string names;
    for (size_t i = 0; i < ignored_columns.size(); ++i) {
      names += (i ? ", '" : "'") + Excerpt(ignored_columns[i]) + "'";
    }
    description["warnings"].push_back(
        std::to_string(ignored_columns.size()) +
        " column(s) of the file not read (neither named in config 'columns' nor a calibd "
        "column name): " +
        names);
  }
  summary.log_description =
      description.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

Status RecordingParser::Impl::PcaHeader() {
  const auto& f = fields;
  const bool raw = f.size() > 1 && f[1] == "phase";
  summary.layout = raw ? Layout::kPcaRaw : Layout::kPcaAveraged;
  first_sensor_col = raw ? 2 : 1;
  std::unordered_map<std::string_view, size_t> seen;
  for (size_t i = first_sensor_col; i < f.size(); ++i) {
    const int64_t col = static_cast<int64_t>(i) + 1;
    if (f[i].empty()) return Fail("empty sensor name in the header", col);
    if (f[i] == "position" || f[i] == "phase") {
      return Fail("'" + std::string(f[i]) + "' may only be the first" +
                      (f[i] == "phase" ? std::string(" or second") : std::string()) + " column",
                  col);
    }
    auto [it, inserted] = seen.emplace(f[i], i);
    if (!inserted) {
      return Fail("duplicate sensor name '" + Excerpt(f[i]) + "' (also column " +
                      std::to_string(it->second + 1) + ")",
                  col, std::string(f[i]));
    }
    summary.sensors.emplace_back(f[i]);
  }
  sensor_count = summary.sensors.size();
  if (sensor_count == 0) {
    return Fail(std::string("no sensor columns after '") + (raw ? "phase" : "position") + "'");
  }
  row_values.resize(sensor_count);
  return Status::Ok();
}

Status RecordingParser::Impl::ArrayHeader() {
  const auto& f = fields;
  summary.layout = Layout::kArray;
  std::vector<std::array<int64_t, 3>> accel_cols, gyro_cols, mag_cols;  // file column per axis
  std::vector<int64_t> temp_cols;  // file column of temp_names[j]
  temp_names.clear();
  int64_t t_col = 0;
  for (size_t i = 0; i < f.size(); ++i) {
    const int64_t col = static_cast<int64_t>(i) + 1;
    const std::string name(f[i]);
    if (name == "t") {
      if (t_col)
        return Fail("duplicate column 't' (also column " + std::to_string(t_col) + ")", col, name);
      t_col = col;
      continue;
    }
    if (IsTemperatureColumn(f[i])) {
      for (size_t j = 0; j < temp_cols.size(); ++j) {
        if (temp_names[j] == name) {
          return Fail(
              "duplicate column '" + name + "' (also column " + std::to_string(temp_cols[j]) + ")",
              col, name);
        }
      }
      temp_cols.push_back(col);
      temp_names.push_back(name);
      continue;
    }
    char kind;
    int index, axis;
    if (!ParseTriadColumn(f[i], &kind, &index, &axis)) {
      if (!dialect.columns.empty()) {  // a mapping names what is read; the rest is ignored
        ignored_columns.push_back(name);
        continue;
      }
      return Fail("unknown column '" + Excerpt(f[i]) +
                      "': an array recording has columns t, aK_x, aK_y, aK_z (accelerometer "
                      "triad K), gJ_x, gJ_y, gJ_z (gyroscope triad J), mJ_x, mJ_y, mJ_z "
                      "(magnetometer triad J) and temp or tempK (temperature, °C); a pca "
                      "recording starts with 'position'",
                  col, name);
    }
    if (index >= limits.max_columns) {
      return Fail("triad index " + std::to_string(index) + " is too large", col, name);
    }
    auto& cols = kind == 'a' ? accel_cols : (kind == 'g' ? gyro_cols : mag_cols);
    if (static_cast<int>(cols.size()) <= index) cols.resize(index + 1, {0, 0, 0});
    if (cols[index][axis]) {
      return Fail(
          "duplicate column '" + name + "' (also column " + std::to_string(cols[index][axis]) + ")",
          col, name);
    }
    cols[index][axis] = col;
  }
  for (char kind : {'a', 'g', 'm'}) {
    const auto& cols = kind == 'a' ? accel_cols : (kind == 'g' ? gyro_cols : mag_cols);
    for (size_t k = 0; k < cols.size(); ++k) {
      for (int axis = 0; axis < 3; ++axis) {
        if (!cols[k][axis]) {
          const std::string missing = std::string(1, kind) + std::to_string(k) + "_" + kAxes[axis];
          return Fail("missing column '" + missing + "': triads are numbered from 0 without " +
                          "gaps and each needs _x, _y and _z",
                      0, missing);
        }
      }
    }
  }
  if (accel_cols.empty() && mag_cols.empty()) {
    return Fail("no accelerometer or magnetometer columns (a0_x, a0_y, a0_z, ... or m0_x, ...)");
  }
  accel_triads = static_cast<int>(accel_cols.size());
  gyro_triads = static_cast<int>(gyro_cols.size());
  mag_triads = static_cast<int>(mag_cols.size());
  has_t = t_col != 0;
  t_column = t_col;
  summary.t_column = t_col;
  column_target.assign(f.size(), kIgnoredColumn);
  if (t_col) column_target[t_col - 1] = kTimeColumn;
  for (int k = 0; k < accel_triads; ++k) {
    for (int axis = 0; axis < 3; ++axis) column_target[accel_cols[k][axis] - 1] = 3 * k + axis;
  }
  for (int j = 0; j < gyro_triads; ++j) {
    for (int axis = 0; axis < 3; ++axis) {
      column_target[gyro_cols[j][axis] - 1] = 3 * accel_triads + 3 * j + axis;
    }
  }
  for (int k = 0; k < accel_triads; ++k) summary.sensors.push_back("a" + std::to_string(k));
  for (int j = 0; j < gyro_triads; ++j) summary.sensors.push_back("g" + std::to_string(j));
  const int triads = accel_triads + gyro_triads + mag_triads;
  for (int j = 0; j < mag_triads; ++j) {
    for (int axis = 0; axis < 3; ++axis) {
      column_target[mag_cols[j][axis] - 1] = 3 * (accel_triads + gyro_triads + j) + axis;
    }
    summary.sensors.push_back("m" + std::to_string(j));
  }
  for (size_t j = 0; j < temp_cols.size(); ++j) {
    column_target[temp_cols[j] - 1] = 3 * triads + static_cast<int>(j);
  }
  row_values.resize(3 * triads + temp_names.size());
  StartDirectCollection();
  return Status::Ok();
}

void RecordingParser::Impl::StartDirectCollection() {
  const int64_t width = static_cast<int64_t>(row_values.size());
  // At most 2^30 values (8 GiB) up front, whatever the hint says (the job budget of
  // server/job_budget.h bounds real jobs far below that).
  if (collect && expected_rows > 0 && expected_rows <= (int64_t{1} << 30) / width) {
    direct = true;
    if (as_float) {
      direct_accel_f.resize(expected_rows, 3 * accel_triads);
      direct_gyro_f.resize(expected_rows, 3 * gyro_triads);
    } else {
      direct_accel.resize(expected_rows, 3 * accel_triads);
      direct_gyro.resize(expected_rows, 3 * gyro_triads);
    }
    if (has_t) direct_t.resize(expected_rows);
    direct_side.resize(expected_rows,
                       static_cast<Eigen::Index>(3 * mag_triads + temp_names.size()));
  }
}

Status RecordingParser::Impl::PcaRow() {
  const auto& f = fields;
  const size_t expected = first_sensor_col + sensor_count;
  if (f.size() != expected) return RowShapeError(f.size(), expected);
  if (f[0].empty()) return Fail("empty position label", 1, "position");
  if (!IsValidUtf8(f[0])) return Fail("position label is not valid UTF-8", 1, "position");
  if (const int c = FirstControlCharacter(f[0]); c >= 0) {
    return Fail("position label '" + Excerpt(f[0]) + "' contains the control character " +
                    ControlName(c) + "; labels must be printable",
                1, "position");
  }
  bool moving = true;
  if (first_sensor_col == 2) {
    if (f[1] == "static") {
      moving = false;
    } else if (f[1] != "moving") {
      return Fail("phase must be 'static' or 'moving', not '" + Excerpt(f[1]) + "'", 2, "phase");
    }
  }
  for (size_t i = 0; i < sensor_count; ++i) {
    const size_t col = first_sensor_col + i;
    Status s =
        ParseNumber(f[col], static_cast<int64_t>(col) + 1, summary.sensors[i], &row_values[i]);
    if (!s.ok()) return s;
  }
  return CommitPcaRow(f[0], moving) ? Status::Ok() : error;
}

Status RecordingParser::Impl::ArrayRow() {
  const auto& f = fields;
  if (f.size() != column_target.size()) return RowShapeError(f.size(), column_target.size());
  double t = 0;
  std::string_view t_text;
  for (size_t i = 0; i < f.size(); ++i) {
    const int target = column_target[i];
    if (target == kIgnoredColumn) continue;
    double* dst = target == kTimeColumn ? &t : &row_values[target];
    Status s = ParseNumber(f[i], static_cast<int64_t>(i) + 1, summary.columns[i], dst);
    if (!s.ok()) return s;
    if (target == kTimeColumn) t_text = f[i];
  }
  CommitArrayRow(t, t_text);
  return Status::Ok();
}

}  // namespace calibd::server
