// Strict, incremental CSV parser for the recording layouts of SPEC §2.
//
// Lines are cut out of the incoming chunks without copying unless a line straddles two chunks;
// fields are string_views into the line; numbers go through std::from_chars (libstdc++ 12: the
// fast_float algorithm, correctly rounded). Column numbers in errors are 1-based field numbers.
#include "formats/recording.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <unordered_map>

namespace calibd::server {

const char* LayoutName(Layout layout) {
  switch (layout) {
    case Layout::kPcaAveraged:
      return "pca_averaged";
    case Layout::kPcaRaw:
      return "pca_raw";
    case Layout::kArray:
      return "array";
  }
  return "unknown";
}

const char* TimeUnitName(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kSeconds:
      return "s";
    case TimeUnit::kMilliseconds:
      return "ms";
    case TimeUnit::kMicroseconds:
      return "us";
    case TimeUnit::kNanoseconds:
      return "ns";
  }
  return "s";
}

bool TimeUnitFromName(std::string_view name, TimeUnit* unit) {
  for (TimeUnit u : {TimeUnit::kSeconds, TimeUnit::kMilliseconds, TimeUnit::kMicroseconds,
                     TimeUnit::kNanoseconds}) {
    if (name == TimeUnitName(u)) {
      *unit = u;
      return true;
    }
  }
  return false;
}

int TimeUnitDigits(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kSeconds:
      return 0;
    case TimeUnit::kMilliseconds:
      return 3;
    case TimeUnit::kMicroseconds:
      return 6;
    case TimeUnit::kNanoseconds:
      return 9;
  }
  return 0;
}

namespace {

// A decimal time stamp ([+|-]digits[.digits][(e|E)[+|-]digits], as the parser accepted it) split
// exactly into its integer part and its fraction (both with the stamp's sign; the fraction
// correctly rounded). false for any other shape, or an integer part beyond int64 (9.2e18).
// `buffer`: scratch, reused.
bool SplitDecimal(std::string_view text, std::string* buffer, int64_t* integer, double* fraction) {
  size_t i = 0;
  bool negative = false;
  if (i < text.size() && (text[i] == '-' || text[i] == '+')) negative = text[i++] == '-';
  std::string& digits = *buffer;
  digits.clear();
  int64_t point = -1;  // digits before the decimal point
  for (; i < text.size(); ++i) {
    const char c = text[i];
    if (c >= '0' && c <= '9') {
      if (digits.size() >= 400) return false;
      digits.push_back(c);
    } else if (c == '.' && point < 0) {
      point = static_cast<int64_t>(digits.size());
    } else {
      break;
    }
  }
  if (digits.empty()) return false;
  if (point < 0) point = static_cast<int64_t>(digits.size());
  if (i < text.size()) {
    if (text[i] != 'e' && text[i] != 'E') return false;
    ++i;
    bool exponent_negative = false;
    if (i < text.size() && (text[i] == '-' || text[i] == '+')) exponent_negative = text[i++] == '-';
    if (i == text.size()) return false;
    int64_t exponent = 0;
    for (; i < text.size(); ++i) {
      if (text[i] < '0' || text[i] > '9') return false;
      exponent = exponent * 10 + (text[i] - '0');
      if (exponent > 400) return false;
    }
    point += exponent_negative ? -exponent : exponent;
  }
  const int64_t n = static_cast<int64_t>(digits.size());
  uint64_t whole = 0;  // at most 19 digits: below 10^19 < 2^64
  int significant = 0;
  for (int64_t k = 0; k < point; ++k) {
    const char c = k < n ? digits[static_cast<size_t>(k)] : '0';
    if (significant == 0 && c == '0') continue;
    if (++significant > 19) return false;
    whole = whole * 10 + static_cast<uint64_t>(c - '0');
  }
  if (whole > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) return false;
  double frac = 0;
  if (point < n) {
    std::string rest = "0.";
    if (point < 0) rest.append(static_cast<size_t>(-point), '0');
    rest.append(digits, static_cast<size_t>(std::max<int64_t>(point, 0)), std::string::npos);
    std::from_chars(rest.data(), rest.data() + rest.size(), frac);
  }
  *integer = negative ? -static_cast<int64_t>(whole) : static_cast<int64_t>(whole);
  *fraction = negative ? -frac : frac;
  return true;
}

// The decimal `text` times 10^-digits, correctly rounded (its exponent lowered by `digits`, then
// one std::from_chars): "10" ms gives the very double "0.01" s gives. false when it cannot.
bool ScaledDecimal(std::string_view text, int digits, std::string* buffer, double* value) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  const size_t e = text.find_first_of("eE");
  long exponent = 0;
  if (e != std::string_view::npos) {
    std::string_view x = text.substr(e + 1);
    if (!x.empty() && x.front() == '+') x.remove_prefix(1);
    auto [ptr, ec] = std::from_chars(x.data(), x.data() + x.size(), exponent);
    if (ec != std::errc() || ptr != x.data() + x.size() || exponent > 100000 ||
        exponent < -100000) {
      return false;
    }
  }
  buffer->assign(text.substr(0, e));
  buffer->push_back('e');
  buffer->append(std::to_string(exponent - digits));
  double v = 0;
  auto [ptr, ec] = std::from_chars(buffer->data(), buffer->data() + buffer->size(), v);
  if (ec != std::errc() || ptr != buffer->data() + buffer->size() || !std::isfinite(v)) {
    return false;
  }
  *value = v;
  return true;
}

}  // namespace

bool LayoutFromName(std::string_view name, Layout* layout) {
  for (Layout l : {Layout::kPcaAveraged, Layout::kPcaRaw, Layout::kArray}) {
    if (name == LayoutName(l)) {
      *layout = l;
      return true;
    }
  }
  return false;
}

namespace {

constexpr char kAxes[] = {'x', 'y', 'z'};

std::string_view TrimSpaces(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

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

// Parses "a12_x" style names. kind is 'a' or 'g'; returns false if the name has another form.
bool ParseTriadColumn(std::string_view name, char* kind, int* index, int* axis) {
  if (name.size() < 4 || (name[0] != 'a' && name[0] != 'g')) return false;
  const size_t underscore = name.find('_');
  if (underscore == std::string_view::npos || underscore < 2 || underscore + 2 != name.size()) {
    return false;
  }
  const std::string_view digits = name.substr(1, underscore - 1);
  if (digits.size() > 1 && digits[0] == '0') return false;  // "a01_x" is not a0/a1
  int value = 0;
  auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (ec != std::errc() || ptr != digits.data() + digits.size() || value < 0) return false;
  const char axis_char = name.back();
  if (axis_char < 'x' || axis_char > 'z') return false;
  *kind = name[0];
  *index = value;
  *axis = axis_char - 'x';
  return true;
}

}  // namespace

namespace {

// Appends the decimal digits starting at p to *mantissa (wrapping past 2^64: the caller rejects
// more than 19 digits anyway) and returns the first non-digit. Where 8 bytes are readable it
// works on a word at a time (SWAR): one load finds the run of up to 8 leading digits and three
// multiplications turn it into a number, so a typical sensor value costs no per-digit loop.
inline const char* AccumulateDigits(const char* p, const char* end, uint64_t* mantissa) {
  static constexpr uint64_t kPow10[] = {1,      10,      100,      1000,     10000,
                                        100000, 1000000, 10000000, 100000000};
  uint64_t m = *mantissa;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  while (end - p >= 8) {
    uint64_t chunk;
    std::memcpy(&chunk, p, 8);  // byte 0 is the first character
    // A byte is a digit when its high nibble is 3 and stays 3 after adding 6. A carry out of a
    // non-digit byte can only disturb the bytes after it, which are not used.
    const uint64_t non_digit =
        ((chunk & 0xF0F0F0F0F0F0F0F0u) ^ 0x3030303030303030u) |
        (((chunk + 0x0606060606060606u) & 0xF0F0F0F0F0F0F0F0u) ^ 0x3030303030303030u);
    const int n = non_digit == 0 ? 8 : __builtin_ctzll(non_digit) / 8;  // leading digits
    // The n digit values moved to the top bytes (zeros before them are leading zeros), then
    // combined pairwise: 10·d0 + d1 in every other byte, then all eight as one number. No
    // branch on n (0 included): digit counts vary from number to number.
    const uint64_t values = chunk - 0x3030303030303030u;
    uint64_t d = n == 0 ? 0 : values << (8 * (8 - n));
    d = d * 10 + (d >> 8);
    d = (((d & 0x000000FF000000FFu) * (100 + (1000000ull << 32))) +
         (((d >> 16) & 0x000000FF000000FFu) * (1 + (10000ull << 32)))) >>
        32;
    m = m * kPow10[n] + d;
    p += n;
    if (n < 8) {
      *mantissa = m;
      return p;
    }
  }
#endif
  for (; p < end && static_cast<unsigned>(*p - '0') < 10; ++p) {
    m = m * 10 + static_cast<uint64_t>(*p - '0');
  }
  *mantissa = m;
  return p;
}

// Inlined into the row reader; ParseDecimalPrefixFast below is the exported name.
inline const char* DecimalPrefixFast(const char* p, const char* end, double* value) {
  // Clinger's fast path: a decimal with at most 19 significant digits whose integer mantissa M
  // is exactly representable (M <= 2^53) and whose decimal exponent E has |E| <= 22 is the
  // correctly rounded M * 10^E or M / 10^-E, one IEEE operation on two exact operands.
  static constexpr double kPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                      1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                      1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
  const bool negative = p < end && *p == '-';
  p += negative;  // branch-free: signs are random in sensor data
  uint64_t mantissa = 0;
  int exponent = 0;
  const char* const start = p;
  // Counting every digit (leading zeros too) keeps the loops branch-light; the rare number with
  // more than 19 digits in all goes to std::from_chars.
  p = AccumulateDigits(p, end, &mantissa);
  ptrdiff_t digits = p - start;
  if (p < end && *p == '.') {
    ++p;
    const char* const frac = p;
    p = AccumulateDigits(p, end, &mantissa);
    exponent = -static_cast<int>(p - frac);
    digits += p - frac;
  }
  if (digits == 0) return nullptr;
  if (p < end && (*p == 'e' || *p == 'E')) {
    ++p;
    bool exp_negative = false;
    if (p < end && (*p == '+' || *p == '-')) exp_negative = *p++ == '-';
    const char* const exp_start = p;
    int e = 0;
    for (; p < end && static_cast<unsigned>(*p - '0') < 10; ++p) {
      e = e * 10 + (*p - '0');
      if (e > 10000) return nullptr;
    }
    if (p == exp_start) return nullptr;
    exponent += exp_negative ? -e : e;
  }
  if (digits > 19 || mantissa > (uint64_t{1} << 53) || exponent < -22 || exponent > 22) {
    return nullptr;
  }
  double v = static_cast<double>(mantissa);
  v = exponent < 0 ? v / kPow10[-exponent] : v * kPow10[exponent];
  uint64_t bits;  // v >= 0: set the sign bit without a branch (-0 stays -0)
  std::memcpy(&bits, &v, sizeof bits);
  bits |= static_cast<uint64_t>(negative) << 63;
  std::memcpy(value, &bits, sizeof bits);
  return p;
}

}  // namespace

const char* ParseDecimalPrefixFast(const char* p, const char* end, double* value) {
  return DecimalPrefixFast(p, end, value);
}

bool ParseDecimalFast(std::string_view text, double* value) {
  const char* const end = text.data() + text.size();
  double v = 0;
  if (ParseDecimalPrefixFast(text.data(), end, &v) != end) return false;
  *value = v;
  return true;
}

struct RecordingParser::Impl {
  std::string file_name;
  bool collect;
  RecordingLimits limits;

  Status error;  // sticky first error
  bool finished = false;
  std::string carry;     // an incomplete line from the previous chunk
  int64_t line_no = 0;   // physical line number of the line being parsed
  bool at_start = true;  // BOM check pending
  bool have_header = false;
  RecordingSummary summary;
  std::vector<std::string_view> fields;  // reused per line
  std::vector<std::string> unquoted;     // storage for fields that had quotes (see Split)
  std::string_view line_text;            // the line on the general path (for error hints)

  // pca
  int first_sensor_col = 1;  // 1 (averaged) or 2 (raw)
  size_t sensor_count = 0;
  struct Position {
    std::string label;
    int64_t first_line;
    int64_t static_rows = 0, moving_rows = 0, rows = 0;
  };
  std::vector<Position> positions;
  std::unordered_map<std::string, size_t> position_index;
  size_t last_position = 0;                    // index of the previous row's position
  std::vector<double> moving_sum, static_sum;  // n*m, position-major (collect only)
  std::vector<double> row_values;              // reused

  // array: for each file column, the destination (-1 = t, otherwise index into the row layout
  // a0_x..a{K-1}_z, g0_x..g{G-1}_z).
  std::vector<int> column_target;
  int accel_triads = 0, gyro_triads = 0;
  bool has_t = false;
  int64_t t_column = 0;       // 1-based, when has_t
  double previous_t = 0;      // seconds (converted), as collected
  double previous_raw_t = 0;  // as the file writes it
  bool have_previous_t = false;
  // The time column's unit (SetTimeUnit): seconds = value / time_divisor.
  TimeUnit time_unit = TimeUnit::kSeconds;
  int time_digits = 0;
  double time_divisor = 1;
  int64_t time_divisor_int = 1;
  // Epoch stamps (StartTime): every t is read exactly and counted from time_origin_units (the
  // first stamp's whole second, in the file's unit).
  bool time_shifted = false;
  int64_t time_origin_units = 0;
  std::vector<double> time_steps;    // the first kTimeProbeRows - 1 steps of t, file units
  std::string time_buffer;           // scratch of the exact time readers
  std::vector<double> array_values;  // N * (3K+3G), row-major (collect only)
  std::vector<double> t_values;
  int64_t expected_rows = 0;  // ExpectRows: the announced number of data rows (0: unknown)
  // Direct collection (ExpectRows, array layout): rows go straight into the column-major
  // matrices TakeArray hands out, so the numbers are held once, never also as a row-major
  // buffer. If more rows come than announced, the rows so far move to array_values and the
  // parser goes on as without the hint.
  bool direct = false;
  int64_t direct_rows = 0;  // rows written into the matrices
  Eigen::MatrixXd direct_accel, direct_gyro;
  Eigen::VectorXd direct_t;
  // CollectArrayAsFloat: the array numbers times the scale of their kind (in double), rounded
  // once to float, in these instead of the double buffers above (t stays double).
  bool as_float = false;
  double float_scale_accel = 1, float_scale_gyro = 1;
  std::vector<float> array_values_f;  // row-major, as array_values
  Eigen::MatrixXf direct_accel_f, direct_gyro_f;

  // Hands the collected array to `out` (an ArrayRecording or ArrayRecordingFloat: TakeArray,
  // TakeArrayFloat) from the members that collected it, `acc`, `gyr` and `values` (the double or
  // the float ones): the preallocated matrices without a copy when the row hint was exact (their
  // first direct_rows rows when fewer came), else the row-major values split into accelerometer
  // and gyroscope columns. The parser's copies are released.
  template <typename Out, typename Matrix, typename Scalar>
  void HandOverArray(Matrix* acc, Matrix* gyr, std::vector<Scalar>* values, Out* out) {
    out->accel_names.assign(summary.sensors.begin(), summary.sensors.begin() + accel_triads);
    out->gyro_names.assign(summary.sensors.begin() + accel_triads, summary.sensors.end());
    if (direct) {
      // Handed over without a copy when the hint was exact (fewer rows: the rows there are).
      if (direct_rows == acc->rows()) {
        out->accel = std::move(*acc);
        out->gyro = std::move(*gyr);
        out->t = has_t ? std::move(direct_t) : Eigen::VectorXd();
      } else {
        out->accel = acc->topRows(direct_rows);
        out->gyro = gyr->topRows(direct_rows);
        out->t = has_t ? Eigen::VectorXd(direct_t.head(direct_rows)) : Eigen::VectorXd();
      }
      direct = false;
      acc->resize(0, 0);
      gyr->resize(0, 0);
      direct_t.resize(0);
      return;
    }
    const int width = 3 * (accel_triads + gyro_triads);
    Eigen::Map<const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> all(
        values->data(), summary.rows, width);
    out->accel = all.leftCols(3 * accel_triads);
    out->gyro = all.rightCols(3 * gyro_triads);
    if (has_t) {
      out->t = Eigen::Map<const Eigen::VectorXd>(t_values.data(), summary.rows);
    } else {
      out->t.resize(0);
    }
    std::vector<Scalar>().swap(*values);
    std::vector<double>().swap(t_values);
  }

  Status Fail(std::string message, int64_t column = 0, std::string field = {}) {
    Status s = Status::InvalidInput(std::move(message));
    s.WithFile(file_name).WithLocation(line_no, column);
    if (!field.empty()) s.WithField(std::move(field));
    error = s;
    return s;
  }

  // Splits `line` at commas into `fields`, honouring RFC 4180 double quotes within the line.
  Status Split(std::string_view line) {
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
      while (lead < line.size() && (line[lead] == ' ' || line[lead] == '\t')) ++lead;
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
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
        if (i < line.size() && line[i] != ',') {
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
        size_t comma = line.find(',', start);
        if (comma == std::string_view::npos) comma = line.size();
        fields.push_back(TrimSpaces(line.substr(start, comma - start)));
        pos = comma;
      }
      if (pos >= line.size()) break;
      ++pos;  // skip the comma
    }
    return Status::Ok();
  }

  // The common case: no quotes anywhere in the line, so fields end at commas.
  Status SplitUnquoted(std::string_view line) {
    const char* p = line.data();
    const char* const end = p + line.size();
    while (true) {
      if (static_cast<int64_t>(fields.size()) >= limits.max_columns) {
        return Fail("more than " + std::to_string(limits.max_columns) + " columns",
                    static_cast<int64_t>(fields.size()) + 1);
      }
      const char* comma = static_cast<const char*>(memchr(p, ',', static_cast<size_t>(end - p)));
      const char* field_end = comma ? comma : end;
      fields.push_back(TrimSpaces(std::string_view(p, static_cast<size_t>(field_end - p))));
      if (!comma) break;
      p = comma + 1;
    }
    return Status::Ok();
  }

  Status ParseNumber(std::string_view text, int64_t column, const std::string& name,
                     double* value) {
    if (text.empty()) return Fail("empty cell in column '" + name + "'", column, name);
    std::string_view digits = text;
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
                        "'): " + kCsvExportAdvice,
                    column, name);
      }
      if (IsDecimalCommaNumber(text)) {
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

  // A row with the wrong number of fields; names a foreign separator or a decimal comma, the
  // usual causes in spreadsheet exports.
  Status RowShapeError(size_t got, size_t expected) {
    const std::string counts =
        "row has " + std::to_string(got) + " fields, the header has " + std::to_string(expected);
    const int64_t column = static_cast<int64_t>(std::min(got, expected)) + 1;
    size_t at = 0;
    if (const char sep = ForeignSeparator(line_text, &at); sep != 0) {
      return Fail("line " + std::to_string(line_no) + " uses " + SeparatorName(sep) +
                      " as the separator (first at character " + std::to_string(at) + "; " +
                      counts + "): " + kCsvExportAdvice,
                  column);
    }
    if (got > expected) {
      return Fail(
          counts + ": if ',' is the decimal mark here (e.g. '1,5' for 1.5), " + kCsvExportAdvice,
          column);
    }
    return Fail(counts, column);
  }

  // A header line without a comma that uses ';' or tabs: a spreadsheet's export.
  bool ForeignHeader(std::string_view line) {
    size_t at = 0;
    const char sep = line.find(',') == std::string_view::npos ? ForeignSeparator(line, &at) : 0;
    if (sep == 0) return false;
    Fail("line " + std::to_string(line_no) + " uses " + SeparatorName(sep) +
             " as the separator (first at character " + std::to_string(at) +
             "): " + kCsvExportAdvice,
         1);
    return true;
  }

  Status Header() {
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
    if (f[0] == "position") {
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
    // array layout: t and triad columns in any order.
    summary.layout = Layout::kArray;
    std::vector<std::array<int64_t, 3>> accel_cols, gyro_cols;  // file column per axis, 0 = none
    int64_t t_col = 0;
    for (size_t i = 0; i < f.size(); ++i) {
      const int64_t col = static_cast<int64_t>(i) + 1;
      const std::string name(f[i]);
      if (name == "t") {
        if (t_col)
          return Fail("duplicate column 't' (also column " + std::to_string(t_col) + ")", col,
                      name);
        t_col = col;
        continue;
      }
      char kind;
      int index, axis;
      if (!ParseTriadColumn(f[i], &kind, &index, &axis)) {
        return Fail("unknown column '" + Excerpt(f[i]) +
                        "': an array recording has columns t, aK_x, aK_y, aK_z (accelerometer "
                        "triad K) and gJ_x, gJ_y, gJ_z (gyroscope triad J); a pca recording "
                        "starts with 'position'",
                    col, name);
      }
      if (index >= limits.max_columns) {
        return Fail("triad index " + std::to_string(index) + " is too large", col, name);
      }
      auto& cols = kind == 'a' ? accel_cols : gyro_cols;
      if (static_cast<int>(cols.size()) <= index) cols.resize(index + 1, {0, 0, 0});
      if (cols[index][axis]) {
        return Fail("duplicate column '" + name + "' (also column " +
                        std::to_string(cols[index][axis]) + ")",
                    col, name);
      }
      cols[index][axis] = col;
    }
    for (char kind : {'a', 'g'}) {
      const auto& cols = kind == 'a' ? accel_cols : gyro_cols;
      for (size_t k = 0; k < cols.size(); ++k) {
        for (int axis = 0; axis < 3; ++axis) {
          if (!cols[k][axis]) {
            const std::string missing =
                std::string(1, kind) + std::to_string(k) + "_" + kAxes[axis];
            return Fail("missing column '" + missing + "': triads are numbered from 0 without " +
                            "gaps and each needs _x, _y and _z",
                        0, missing);
          }
        }
      }
    }
    if (accel_cols.empty()) {
      return Fail("no accelerometer columns (a0_x, a0_y, a0_z, ...)");
    }
    accel_triads = static_cast<int>(accel_cols.size());
    gyro_triads = static_cast<int>(gyro_cols.size());
    has_t = t_col != 0;
    t_column = t_col;
    summary.t_column = t_col;
    column_target.assign(f.size(), -1);
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
    row_values.resize(3 * (accel_triads + gyro_triads));
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
    }
    return Status::Ok();
  }

  Status PcaRow() {
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

  // Adds the row in row_values, of position `label`, to its position; false (and `error`) when
  // that would be one position too many.
  bool CommitPcaRow(std::string_view label, bool moving) {
    // Rows of one position usually come together: try the previous row's position first.
    size_t p;
    if (!positions.empty() && positions[last_position].label == label) {
      p = last_position;
    } else if (auto it = position_index.find(std::string(label)); it != position_index.end()) {
      p = it->second;
    } else {
      if (static_cast<int64_t>(positions.size()) >= limits.max_positions) {
        Fail("more than " + std::to_string(limits.max_positions) + " distinct positions", 1,
             "position");
        return false;
      }
      p = positions.size();
      position_index.emplace(std::string(label), p);
      positions.push_back({std::string(label), line_no});
      if (collect) {
        moving_sum.resize(moving_sum.size() + sensor_count, 0.0);
        static_sum.resize(static_sum.size() + sensor_count, 0.0);
      }
    }
    last_position = p;
    Position& pos = positions[p];
    ++pos.rows;
    (moving ? pos.moving_rows : pos.static_rows)++;
    if (collect) {
      double* sum = (moving ? moving_sum.data() : static_sum.data()) + p * sensor_count;
      for (size_t i = 0; i < sensor_count; ++i) sum[i] += row_values[i];
    }
    return true;
  }

  Status ArrayRow() {
    const auto& f = fields;
    if (f.size() != column_target.size()) return RowShapeError(f.size(), column_target.size());
    double t = 0;
    std::string_view t_text;
    for (size_t i = 0; i < f.size(); ++i) {
      const int target = column_target[i];
      double* dst = target < 0 ? &t : &row_values[target];
      Status s = ParseNumber(f[i], static_cast<int64_t>(i) + 1, summary.columns[i], dst);
      if (!s.ok()) return s;
      if (target < 0) t_text = f[i];
    }
    CommitArrayRow(t, t_text);
    return Status::Ok();
  }

  // At the first stamp: counts the times from its whole second when it is far from 0 (epoch
  // stamps; RecordingSummary::time_origin).
  void StartTime(double raw, std::string_view text) {
    if (!(std::fabs(raw) / time_divisor >= kTimeOriginSeconds)) return;
    int64_t whole = 0;
    double fraction = 0;
    if (!SplitDecimal(text, &time_buffer, &whole, &fraction)) {
      // Not a plain decimal within int64: the origin from the double (the stamps then go
      // through it too, TimeSeconds).
      if (!(std::fabs(raw) < 9e18)) return;
      whole = static_cast<int64_t>(raw);
    }
    int64_t seconds = whole / time_divisor_int;
    if (whole % time_divisor_int < 0) --seconds;  // floor
    // The origin in the log's units must fit int64 (a first stamp near -9.2e18 ns would not).
    const __int128 units = static_cast<__int128>(seconds) * time_divisor_int;
    if (units < std::numeric_limits<int64_t>::min() ||
        units > std::numeric_limits<int64_t>::max()) {
      return;
    }
    time_shifted = true;
    time_origin_units = static_cast<int64_t>(units);
    summary.time_origin = seconds;
  }

  // The stamp `raw` (parsed from `text`) in seconds from the origin.
  double TimeSeconds(double raw, std::string_view text) {
    if (time_shifted) {
      int64_t whole = 0;
      double fraction = 0;
      if (SplitDecimal(text, &time_buffer, &whole, &fraction)) {
        const __int128 from_origin = static_cast<__int128>(whole) - time_origin_units;
        return (static_cast<double>(from_origin) + fraction) / time_divisor;
      }
      return (raw - static_cast<double>(time_origin_units)) / time_divisor;
    }
    if (time_digits == 0) return raw;  // seconds near 0: exactly as parsed
    double seconds = 0;
    if (ScaledDecimal(text, time_digits, &time_buffer, &seconds)) return seconds;
    return raw / time_divisor;
  }

  // `raw`: the row's t as parsed (0 without a t column); `text`: its text.
  void CommitArrayRow(double raw, std::string_view text) {
    double t = 0;
    if (has_t) {
      if (!have_previous_t) {
        StartTime(raw, text);
        summary.t_first = raw;
        summary.t_first_line = line_no;
      }
      t = TimeSeconds(raw, text);
      if (have_previous_t) {
        if (!(t > previous_t) && summary.t_disorder_line == 0) {
          summary.t_disorder_line = line_no;
          summary.t_disorder_column = t_column;
          summary.t_disorder = raw;
          summary.t_disorder_previous = previous_raw_t;
        }
        if (static_cast<int64_t>(time_steps.size()) < kTimeProbeRows - 1) {
          time_steps.push_back((t - previous_t) * time_divisor);
        }
      }
      previous_t = t;
      previous_raw_t = raw;
      have_previous_t = true;
    }
    if (!collect) return;
    if (direct && direct_rows == expected_rows) LeaveDirectCollection();
    const int ka = 3 * accel_triads, kg = 3 * gyro_triads;
    if (direct) {
      if (as_float) {
        for (int j = 0; j < ka; ++j) direct_accel_f(direct_rows, j) = AccelFloat(row_values[j]);
        for (int j = 0; j < kg; ++j) direct_gyro_f(direct_rows, j) = GyroFloat(row_values[ka + j]);
      } else {
        for (int j = 0; j < ka; ++j) direct_accel(direct_rows, j) = row_values[j];
        for (int j = 0; j < kg; ++j) direct_gyro(direct_rows, j) = row_values[ka + j];
      }
      if (has_t) direct_t(direct_rows) = t;
      ++direct_rows;
      return;
    }
    if (as_float) {
      for (int j = 0; j < ka; ++j) array_values_f.push_back(AccelFloat(row_values[j]));
      for (int j = 0; j < kg; ++j) array_values_f.push_back(GyroFloat(row_values[ka + j]));
    } else {
      array_values.insert(array_values.end(), row_values.begin(), row_values.end());
    }
    if (has_t) t_values.push_back(t);
  }

  float AccelFloat(double v) const { return static_cast<float>(v * float_scale_accel); }
  float GyroFloat(double v) const { return static_cast<float>(v * float_scale_gyro); }

  // More rows than announced: the rows so far move to the row-major buffers.
  void LeaveDirectCollection() {
    const int ka = 3 * accel_triads, kg = 3 * gyro_triads;
    if (as_float) {
      array_values_f.reserve(static_cast<size_t>(2 * direct_rows * (ka + kg)));
    } else {
      array_values.reserve(static_cast<size_t>(2 * direct_rows * (ka + kg)));
    }
    for (int64_t n = 0; n < direct_rows; ++n) {
      if (as_float) {
        for (int j = 0; j < ka; ++j) array_values_f.push_back(direct_accel_f(n, j));
        for (int j = 0; j < kg; ++j) array_values_f.push_back(direct_gyro_f(n, j));
      } else {
        for (int j = 0; j < ka; ++j) array_values.push_back(direct_accel(n, j));
        for (int j = 0; j < kg; ++j) array_values.push_back(direct_gyro(n, j));
      }
      if (has_t) t_values.push_back(direct_t(n));
    }
    direct = false;
    direct_accel.resize(0, 0);
    direct_gyro.resize(0, 0);
    direct_accel_f.resize(0, 0);
    direct_gyro_f.resize(0, 0);
    direct_t.resize(0);
  }

  // The one-pass reader for the common row: plain numbers (no spaces, quotes or '+') after
  // single commas, read straight from the line. It returns kFallback, having changed nothing but
  // row_values, for any other row (quotes included); the general path (Split, ParseNumber) then
  // reads that row and names any error. Both paths give bit-identical values.
  static const char* NextNumber(const char* p, const char* end, bool last, double* value) {
    p = DecimalPrefixFast(p, end, value);
    if (p == nullptr) return nullptr;
    if (last) return p == end ? p : nullptr;
    return p < end && *p == ',' ? p + 1 : nullptr;
  }

  // kRead: the row is read; kFallback: take the general path; kFailed: `error` says why.
  enum class Fast { kRead, kFallback, kFailed };

  Fast FastPcaRow(std::string_view line) {
    const char* p = line.data();
    const char* const end = p + line.size();
    // The label: one pass that also notes quotes and non-ASCII bytes (labels are short).
    const char* q = p;
    bool quote = false, ascii = true, control = false;
    for (; q < end && *q != ','; ++q) {
      const auto u = static_cast<unsigned char>(*q);
      quote |= *q == '"';
      ascii &= u < 0x80;
      control |= u < 0x20 || u == 0x7f;
    }
    if (q == end || q == p) return Fast::kFallback;
    const std::string_view label(p, static_cast<size_t>(q - p));
    if (quote || control || label.front() == ' ' || label.front() == '\t' || label.back() == ' ' ||
        label.back() == '\t' || (!ascii && !IsValidUtf8(label))) {
      return Fast::kFallback;
    }
    p = q + 1;
    bool moving = true;
    if (first_sensor_col == 2) {
      if (end - p >= 7 && std::memcmp(p, "static,", 7) == 0) {
        moving = false;
      } else if (!(end - p >= 7 && std::memcmp(p, "moving,", 7) == 0)) {
        return Fast::kFallback;
      }
      p += 7;
    }
    for (size_t i = 0; i < sensor_count; ++i) {
      p = NextNumber(p, end, i + 1 == sensor_count, &row_values[i]);
      if (p == nullptr) return Fast::kFallback;
    }
    return CommitPcaRow(label, moving) ? Fast::kRead : Fast::kFailed;
  }

  Fast FastArrayRow(std::string_view line) {
    const char* p = line.data();
    const char* const end = p + line.size();
    double t = 0;
    std::string_view t_text;
    const size_t n = column_target.size();
    for (size_t i = 0; i < n; ++i) {
      const int target = column_target[i];
      const char* start = p;
      p = NextNumber(p, end, i + 1 == n, target < 0 ? &t : &row_values[target]);
      if (p == nullptr) return Fast::kFallback;
      if (target < 0)
        t_text = std::string_view(start, static_cast<size_t>(p - start) - (i + 1 == n ? 0 : 1));
    }
    CommitArrayRow(t, t_text);
    return Fast::kRead;
  }

  // Reads one physical line; false when it is invalid, and then `error` says why (every error
  // goes through Fail). A bool, not a Status, because this runs once per row.
  bool Line(std::string_view line) {
    ++line_no;
    if (at_start) {
      at_start = false;
      if (line.size() >= 3 && line.substr(0, 3) == "\xEF\xBB\xBF") line.remove_prefix(3);
    }
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (!line.empty() && line.front() == '#') return true;
    if (TrimSpaces(line).empty()) return true;
    if (have_header && limits.one_pass_rows) {
      const Fast fast = summary.layout == Layout::kArray ? FastArrayRow(line) : FastPcaRow(line);
      if (fast != Fast::kFallback) {
        ++summary.rows;
        return fast == Fast::kRead;
      }
    }
    line_text = line;
    if (!have_header && ForeignHeader(line)) return false;
    if (!Split(line).ok()) return false;
    if (!have_header) {
      have_header = true;
      return Header().ok();
    }
    ++summary.rows;
    return (summary.layout == Layout::kArray ? ArrayRow() : PcaRow()).ok();
  }

  Status Feed(std::string_view chunk) {
    if (!error.ok()) return error;
    if (finished) return Status::Internal("RecordingParser::Feed after Finish");
    while (!chunk.empty()) {
      const size_t nl = chunk.find('\n');
      if (nl == std::string_view::npos) {
        if (static_cast<int64_t>(carry.size() + chunk.size()) > limits.max_line_bytes) {
          ++line_no;
          return Fail("line longer than " + std::to_string(limits.max_line_bytes) + " bytes");
        }
        carry.append(chunk);
        return Status::Ok();
      }
      std::string_view piece = chunk.substr(0, nl);
      chunk.remove_prefix(nl + 1);
      if (static_cast<int64_t>(carry.size() + piece.size()) > limits.max_line_bytes) {
        ++line_no;
        return Fail("line longer than " + std::to_string(limits.max_line_bytes) + " bytes");
      }
      if (carry.empty()) {
        if (!Line(piece)) return error;
      } else {
        carry.append(piece);
        const bool ok = Line(carry);
        carry.clear();
        if (!ok) return error;
      }
    }
    return Status::Ok();
  }

  Status Finish() {
    if (!error.ok()) return error;
    if (finished) return Status::Ok();
    if (!carry.empty()) {
      std::string last = std::move(carry);
      carry.clear();
      if (!Line(last)) return error;
    }
    finished = true;
    if (!have_header) {
      Status s = Status::InvalidInput("empty recording: no header line");
      s.WithFile(file_name);
      return error = s;
    }
    if (summary.rows == 0) {
      Status s = Status::InvalidInput("no data rows after the header");
      s.WithFile(file_name).WithLocation(line_no, 0);
      return error = s;
    }
    if (summary.layout == Layout::kPcaRaw) {
      for (const Position& p : positions) {
        if (p.static_rows == 0 || p.moving_rows == 0) {
          Status s = Status::InvalidInput(
              "position '" + Excerpt(p.label) + "' has no " +
              (p.static_rows == 0 ? "static" : "moving") +
              " rows: the raw layout needs both (static: the bias b'; moving: m')");
          s.WithFile(file_name).WithLocation(p.first_line, 1).WithField("position");
          return error = s;
        }
      }
    }
    if (summary.layout != Layout::kArray)
      summary.positions = static_cast<int64_t>(positions.size());
    if (!time_steps.empty()) {
      auto middle = time_steps.begin() + static_cast<std::ptrdiff_t>(time_steps.size() / 2);
      std::nth_element(time_steps.begin(), middle, time_steps.end());
      summary.t_median_step = *middle;
      std::vector<double>().swap(time_steps);
    }
    return Status::Ok();
  }
};

namespace {
Status NotArray(const std::string& file_name) {
  return Status::InvalidInput(
             "this is a pca recording (first column 'position'), not an array recording "
             "(columns aK_x.., gJ_x..)")
      .WithFile(file_name);
}
}  // namespace

RecordingParser::RecordingParser(std::string file_name, bool collect, RecordingLimits limits)
    : impl_(std::make_unique<Impl>()) {
  impl_->file_name = std::move(file_name);
  impl_->collect = collect;
  impl_->limits = limits;
}

RecordingParser::~RecordingParser() = default;

Status RecordingParser::Feed(std::string_view chunk) { return impl_->Feed(chunk); }
Status RecordingParser::Finish() { return impl_->Finish(); }
const RecordingSummary& RecordingParser::summary() const { return impl_->summary; }

Status RecordingParser::TakePca(PcaRecording* out) {
  Impl& d = *impl_;
  if (!d.finished || !d.error.ok() || !d.collect) {
    return Status::Internal("TakePca needs a successful Finish() of a collecting parser");
  }
  if (d.summary.layout == Layout::kArray) {
    return Status::InvalidInput(
               "this is an array recording (columns aK_x.., gJ_x..), not a pca recording "
               "(first column 'position')")
        .WithFile(d.file_name);
  }
  const size_t m = d.sensor_count, n = d.positions.size();
  out->sensor_names = d.summary.sensors;
  out->position_labels.clear();
  out->raw = d.summary.layout == Layout::kPcaRaw;
  out->readings.resize(m, n);
  out->rows_per_position.clear();
  out->static_rows.clear();
  out->moving_rows.clear();
  if (out->raw)
    out->static_means.resize(m, n);
  else
    out->static_means.resize(0, 0);
  for (size_t p = 0; p < n; ++p) {
    const Impl::Position& pos = d.positions[p];
    out->position_labels.push_back(pos.label);
    out->rows_per_position.push_back(pos.rows);
    for (size_t i = 0; i < m; ++i) {
      const double moving = d.moving_sum[p * m + i] / static_cast<double>(pos.moving_rows);
      if (out->raw) {
        const double bias = d.static_sum[p * m + i] / static_cast<double>(pos.static_rows);
        out->static_means(i, p) = bias;
        out->readings(i, p) = moving - bias;
      } else {
        out->readings(i, p) = moving;
      }
    }
    if (out->raw) {
      out->static_rows.push_back(pos.static_rows);
      out->moving_rows.push_back(pos.moving_rows);
    }
  }
  return Status::Ok();
}

void RecordingParser::ExpectRows(int64_t rows) {
  // A hint only (used up to a cap, so a wrong hint cannot ask for absurd memory): a recording
  // with more rows still parses, as without the hint; one with fewer holds the difference until
  // TakeArray.
  impl_->expected_rows = std::max<int64_t>(rows, 0);
}

Status RecordingParser::TakeArray(ArrayRecording* out) {
  Impl& d = *impl_;
  if (!d.finished || !d.error.ok() || !d.collect) {
    return Status::Internal("TakeArray needs a successful Finish() of a collecting parser");
  }
  if (d.summary.layout != Layout::kArray) return NotArray(d.file_name);
  if (d.as_float) return Status::Internal("the array was collected as float: TakeArrayFloat");
  d.HandOverArray(&d.direct_accel, &d.direct_gyro, &d.array_values, out);
  return Status::Ok();
}

void RecordingParser::CollectArrayAsFloat(double accel_scale, double gyro_scale) {
  if (impl_->have_header) return;  // too late: the numbers are already held as double
  impl_->as_float = true;
  impl_->float_scale_accel = accel_scale;
  impl_->float_scale_gyro = gyro_scale;
}

void RecordingParser::SetTimeUnit(TimeUnit unit) {
  Impl& d = *impl_;
  if (d.have_header) return;  // too late: rows may have been read in the old unit
  d.time_unit = unit;
  d.summary.time_unit = unit;
  d.time_digits = TimeUnitDigits(unit);
  d.time_divisor_int = 1;
  for (int i = 0; i < d.time_digits; ++i) d.time_divisor_int *= 10;
  d.time_divisor = static_cast<double>(d.time_divisor_int);
}

TimeUnit RecordingParser::time_unit() const { return impl_->time_unit; }

bool RecordingParser::collects_float(double* accel_scale, double* gyro_scale) const {
  if (!impl_->as_float) return false;
  if (accel_scale != nullptr) *accel_scale = impl_->float_scale_accel;
  if (gyro_scale != nullptr) *gyro_scale = impl_->float_scale_gyro;
  return true;
}

Status RecordingParser::TakeArrayFloat(ArrayRecordingFloat* out) {
  Impl& d = *impl_;
  if (!d.finished || !d.error.ok() || !d.collect || !d.as_float) {
    return Status::Internal(
        "TakeArrayFloat needs a successful Finish() of a parser collecting floats");
  }
  if (d.summary.layout != Layout::kArray) return NotArray(d.file_name);
  out->accel_scale = d.float_scale_accel;
  out->gyro_scale = d.float_scale_gyro;
  d.HandOverArray(&d.direct_accel_f, &d.direct_gyro_f, &d.array_values_f, out);
  return Status::Ok();
}

Status ParseRecording(std::string_view bytes, RecordingParser* parser) {
  Status s = parser->Feed(bytes);
  if (!s.ok()) return s;
  return parser->Finish();
}

}  // namespace calibd::server
