// The recording parser's rows (formats/recording_parser.h): chunks cut into lines without copying
// unless a line straddles two chunks, the one-pass reader of plain rows (Clinger's fast path on
// a word of digits at a time), the collection of the numbers and the time stamps read exactly.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "formats/recording.h"
#include "formats/recording_parser.h"

namespace calibd::server {

using recording_internal::Excerpt;
using recording_internal::TrimSpaces;

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

bool RecordingParser::Impl::CommitPcaRow(std::string_view label, bool moving) {
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

void RecordingParser::Impl::StartTime(double raw, std::string_view text) {
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
  if (units < std::numeric_limits<int64_t>::min() || units > std::numeric_limits<int64_t>::max()) {
    return;
  }
  time_shifted = true;
  time_origin_units = static_cast<int64_t>(units);
  summary.time_origin = seconds;
}

double RecordingParser::Impl::TimeSeconds(double raw, std::string_view text) {
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

void RecordingParser::Impl::CommitArrayRow(double raw, std::string_view text) {
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
    for (Eigen::Index j = 0; j < direct_side.cols(); ++j) {
      direct_side(direct_rows, j) = row_values[ka + kg + static_cast<size_t>(j)];
    }
    ++direct_rows;
    return;
  }
  if (as_float) {
    for (int j = 0; j < ka; ++j) array_values_f.push_back(AccelFloat(row_values[j]));
    for (int j = 0; j < kg; ++j) array_values_f.push_back(GyroFloat(row_values[ka + j]));
  } else {
    array_values.insert(array_values.end(), row_values.begin(), row_values.begin() + ka + kg);
  }
  side_values.insert(side_values.end(), row_values.begin() + ka + kg, row_values.end());
  if (has_t) t_values.push_back(t);
}

void RecordingParser::Impl::LeaveDirectCollection() {
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
    for (Eigen::Index j = 0; j < direct_side.cols(); ++j) side_values.push_back(direct_side(n, j));
  }
  direct_side.resize(0, 0);
  direct = false;
  direct_accel.resize(0, 0);
  direct_gyro.resize(0, 0);
  direct_accel_f.resize(0, 0);
  direct_gyro_f.resize(0, 0);
  direct_t.resize(0);
}

const char* RecordingParser::Impl::NextNumber(const char* p, const char* end, bool last,
                                              char delimiter, double* value) {
  p = DecimalPrefixFast(p, end, value);
  if (p == nullptr) return nullptr;
  if (last) return p == end ? p : nullptr;
  return p < end && *p == delimiter ? p + 1 : nullptr;
}

RecordingParser::Impl::Fast RecordingParser::Impl::FastPcaRow(std::string_view line) {
  const char* p = line.data();
  const char* const end = p + line.size();
  // The label: one pass that also notes quotes and non-ASCII bytes (labels are short).
  const char* q = p;
  bool quote = false, ascii = true, control = false;
  const char delimiter = dialect.delimiter;
  for (; q < end && *q != delimiter; ++q) {
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
    if (end - p >= 7 && std::memcmp(p, "static", 6) == 0 && p[6] == delimiter) {
      moving = false;
    } else if (!(end - p >= 7 && std::memcmp(p, "moving", 6) == 0 && p[6] == delimiter)) {
      return Fast::kFallback;
    }
    p += 7;
  }
  for (size_t i = 0; i < sensor_count; ++i) {
    p = NextNumber(p, end, i + 1 == sensor_count, delimiter, &row_values[i]);
    if (p == nullptr) return Fast::kFallback;
  }
  return CommitPcaRow(label, moving) ? Fast::kRead : Fast::kFailed;
}

RecordingParser::Impl::Fast RecordingParser::Impl::FastArrayRow(std::string_view line) {
  const char* p = line.data();
  const char* const end = p + line.size();
  double t = 0;
  std::string_view t_text;
  const size_t n = column_target.size();
  const char delimiter = dialect.delimiter;
  for (size_t i = 0; i < n; ++i) {
    const int target = column_target[i];
    const char* start = p;
    if (target == kIgnoredColumn) {  // not read: up to the next delimiter (quotes: general path)
      const char* next = static_cast<const char*>(std::memchr(p, delimiter, end - p));
      if (std::memchr(p, '"', (next ? next : end) - p) != nullptr) return Fast::kFallback;
      if (i + 1 == n) {
        p = next == nullptr ? end : nullptr;
      } else {
        p = next == nullptr ? nullptr : next + 1;
      }
      if (p == nullptr) return Fast::kFallback;
      continue;
    }
    p = NextNumber(p, end, i + 1 == n, delimiter, target == kTimeColumn ? &t : &row_values[target]);
    if (p == nullptr) return Fast::kFallback;
    if (target == kTimeColumn)
      t_text = std::string_view(start, static_cast<size_t>(p - start) - (i + 1 == n ? 0 : 1));
  }
  CommitArrayRow(t, t_text);
  return Fast::kRead;
}

std::string_view RecordingParser::Impl::DecimalPoints(std::string_view line) {
  size_t from = 0;
  if (summary.layout != Layout::kArray) {  // a pca row's label is kept as written
    if (line.find('"') != std::string_view::npos) return line;  // ParseNumber reads each number
    from = line.find(dialect.delimiter);
    if (from == std::string_view::npos) return line;
  }
  decimal_line.assign(line);
  std::replace(decimal_line.begin() + static_cast<std::ptrdiff_t>(from), decimal_line.end(), ',',
               '.');
  return decimal_line;
}

bool RecordingParser::Impl::Line(std::string_view line) {
  ++line_no;
  if (at_start) {
    at_start = false;
    if (line.size() >= 3 && line.substr(0, 3) == "\xEF\xBB\xBF") line.remove_prefix(3);
  }
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  if (!line.empty() && line.front() == '#') return true;
  if (TrimSpaces(line).empty()) return true;
  if (have_header && dialect.decimal == ',') line = DecimalPoints(line);
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
    header_ok = Header().ok();
    return header_ok;
  }
  ++summary.rows;
  return (summary.layout == Layout::kArray ? ArrayRow() : PcaRow()).ok();
}

Status RecordingParser::Impl::Feed(std::string_view chunk) {
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

Status RecordingParser::Impl::Finish() {
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
  if (summary.layout != Layout::kArray) summary.positions = static_cast<int64_t>(positions.size());
  if (!time_steps.empty()) {
    auto middle = time_steps.begin() + static_cast<std::ptrdiff_t>(time_steps.size() / 2);
    std::nth_element(time_steps.begin(), middle, time_steps.end());
    summary.t_median_step = *middle;
    std::vector<double>().swap(time_steps);
  }
  return Status::Ok();
}

}  // namespace calibd::server
