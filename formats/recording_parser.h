// The recording parser's state and stages (RecordingParser::Impl, formats/recording.h), shared
// by its files: recording.cc (names, units and the public RecordingParser), recording_fields.cc
// (the general path: fields, numbers and the header, with their error messages) and
// recording_rows.cc (lines and chunks, the one-pass row reader, collection, time stamps).
// Internal to server/.
#ifndef CALIBD_SERVER_RECORDING_PARSER_H_
#define CALIBD_SERVER_RECORDING_PARSER_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "base/status.h"
#include "formats/csv_dialect.h"
#include "formats/log_assembly.h"
#include "formats/recording.h"
#include "formats/recording_version.h"  // bump it with any change to the reading rules
#include "formats/sensor_log.h"

namespace calibd::server {

namespace recording_internal {

// `s` without its leading and trailing spaces and tabs.
inline std::string_view TrimSpaces(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// Shortens a user string for an error message, so a hostile 1 MiB field does not echo back
// whole; control characters are shown as '?'.
std::string Excerpt(std::string_view s);

}  // namespace recording_internal

// Not thread-safe (as RecordingParser). Every stage that fails sets `error` through Fail.
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
  bool header_ok = false;  // the header line was read without an error
  RecordingSummary summary;
  std::vector<std::string_view> fields;  // reused per line
  std::vector<std::string> unquoted;     // storage for fields that had quotes (see Split)
  std::string_view line_text;            // the line on the general path (for error hints)
  // How the CSV is written (SetCsvDialect). With decimal ',', a data line is read from
  // decimal_line: the line with its commas made points (the label of a pca row kept as it is).
  CsvDialect dialect;
  std::string decimal_line;
  std::vector<std::string> ignored_columns;  // array layout: header columns not read, file order

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

  // array: for each file column, the destination (kTimeColumn = t, kIgnoredColumn = not read
  // (config `columns`), otherwise index into the row layout a0_x..a{K-1}_z, g0_x..g{G-1}_z).
  static constexpr int kTimeColumn = -1, kIgnoredColumn = -2;
  std::vector<int> column_target;
  int accel_triads = 0, gyro_triads = 0;
  int mag_triads = 0;                   // magnetometer triads (row_values after the gyroscopes)
  std::vector<std::string> temp_names;  // temperature columns (row_values after the magnetometers)
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
  // The side columns, always double: the magnetometers' 3M, then the temperatures; row-major
  // N × (3M + temp_names) (or direct, column-major).
  std::vector<double> side_values;
  Eigen::MatrixXd direct_side;

  // Hands the collected array to `out` (an ArrayRecording or ArrayRecordingFloat: TakeArray,
  // TakeArrayFloat) from the members that collected it, `acc`, `gyr` and `values` (the double or
  // the float ones): the preallocated matrices without a copy when the row hint was exact (their
  // first direct_rows rows when fewer came), else the row-major values split into accelerometer
  // and gyroscope columns. The parser's copies are released.
  template <typename Out, typename Matrix, typename Scalar>
  void HandOverArray(Matrix* acc, Matrix* gyr, std::vector<Scalar>* values, Out* out) {
    out->accel_names.assign(summary.sensors.begin(), summary.sensors.begin() + accel_triads);
    out->gyro_names.assign(summary.sensors.begin() + accel_triads,
                           summary.sensors.begin() + accel_triads + gyro_triads);
    out->mag_names.assign(summary.sensors.begin() + accel_triads + gyro_triads,
                          summary.sensors.end());
    out->temp_names = temp_names;
    const auto nm = static_cast<Eigen::Index>(3 * mag_triads);
    const auto nt = static_cast<Eigen::Index>(temp_names.size());
    if (direct) {
      out->mag = direct_side.topLeftCorner(direct_rows, nm);
      out->temperature = direct_side.topRightCorner(direct_rows, nt);
      direct_side.resize(0, 0);
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
    const Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>
        side(side_values.data(), summary.rows, nm + nt);
    out->mag = side.leftCols(nm);
    out->temperature = side.rightCols(nt);
    std::vector<double>().swap(side_values);
    if (has_t) {
      out->t = Eigen::Map<const Eigen::VectorXd>(t_values.data(), summary.rows);
    } else {
      out->t.resize(0);
    }
    std::vector<Scalar>().swap(*values);
    std::vector<double>().swap(t_values);
  }

  // --- The general path (recording_fields.cc).
  // The kInvalidInput `message` at the current line and 1-based `column` (0: none), naming the
  // header `field` when given; it becomes the sticky `error`.
  Status Fail(std::string message, int64_t column = 0, std::string field = {});

  // Splits `line` at commas into `fields`, honouring RFC 4180 double quotes within the line.
  Status Split(std::string_view line);

  // The common case: no quotes anywhere in the line, so fields end at commas.
  Status SplitUnquoted(std::string_view line);

  // The finite number in field `text` of column `column` (header name `name`), a leading '+'
  // allowed; else Fail naming a spreadsheet's separator or decimal comma when it looks like one.
  Status ParseNumber(std::string_view text, int64_t column, const std::string& name, double* value);

  // A row with the wrong number of fields; names a foreign separator or a decimal comma, the
  // usual causes in spreadsheet exports.
  Status RowShapeError(size_t got, size_t expected);

  // A header line without a comma that uses ';' or tabs: a spreadsheet's export (not with a
  // configured delimiter).
  bool ForeignHeader(std::string_view line);
  // Config `columns`: the header's mapped names in `fields` replaced by their calibd names; a
  // mapped name the header lacks, or one that collides with a calibd-named column, fails.
  Status MapHeaderNames();
  // The summary's description of a CSV read with a dialect (RecordingSummary::log_description).
  void DescribeDialect();
  // The data line as the readers take it: with decimal ',', a copy with its commas as points.
  std::string_view DecimalPoints(std::string_view line);
  // The header line in `fields`: the layout, its sensors or triads, and the row layout.
  Status Header();
  // The header of the pca layouts (first field "position"), and of the array layout: t and
  // triad columns in any order.
  Status PcaHeader();
  Status ArrayHeader();
  // With a row hint (ExpectRows) on a collecting parser: the array's matrices allocated for the
  // announced rows, at most 2^30 values (direct collection).
  void StartDirectCollection();
  // A data row in `fields` of the pca layouts, and of the array layout.
  Status PcaRow();
  Status ArrayRow();

  // --- Rows, lines and chunks (recording_rows.cc).
  // Adds the row in row_values, of position `label`, to its position; false (and `error`) when
  // that would be one position too many.
  bool CommitPcaRow(std::string_view label, bool moving);

  // At the first stamp: counts the times from its whole second when it is far from 0 (epoch
  // stamps; RecordingSummary::time_origin).
  void StartTime(double raw, std::string_view text);

  // The stamp `raw` (parsed from `text`) in seconds from the origin.
  double TimeSeconds(double raw, std::string_view text);

  // `raw`: the row's t as parsed (0 without a t column); `text`: its text.
  void CommitArrayRow(double raw, std::string_view text);

  float AccelFloat(double v) const { return static_cast<float>(v * float_scale_accel); }
  float GyroFloat(double v) const { return static_cast<float>(v * float_scale_gyro); }

  // More rows than announced: the rows so far move to the row-major buffers.
  void LeaveDirectCollection();

  // The one-pass reader for the common row: plain numbers (no spaces, quotes or '+') after
  // single commas, read straight from the line. It returns kFallback, having changed nothing but
  // row_values, for any other row (quotes included); the general path (Split, ParseNumber) then
  // reads that row and names any error. Both paths give bit-identical values.
  static const char* NextNumber(const char* p, const char* end, bool last, char delimiter,
                                double* value);

  // kRead: the row is read; kFallback: take the general path; kFailed: `error` says why.
  enum class Fast { kRead, kFallback, kFailed };

  Fast FastPcaRow(std::string_view line);
  Fast FastArrayRow(std::string_view line);

  // Reads one physical line; false when it is invalid, and then `error` says why (every error
  // goes through Fail). A bool, not a Status, because this runs once per row.
  bool Line(std::string_view line);

  // RecordingParser::Feed and RecordingParser::Finish, for CSV.
  Status Feed(std::string_view chunk);
  Status Finish();

  // --- Binary sensor logs (recording_log.cc; SPEC §9). The first kSniffBytes bytes decide
  // (SniffLogFormat): a log is held whole until Finish, then read by its format's reader and
  // assembled (formats/log_assembly.h); anything else goes to the CSV stages above.
  static constexpr size_t kSniffBytes = 16;
  bool sniffed = false;
  std::string head;  // the first bytes, until sniffed
  LogFormat log_format = LogFormat::kUnknown;
  std::string log_bytes;           // the whole log, until Finish
  LogStreamSelection log_streams;  // config `streams` (SetLogStreams)
  ArrayRecording log_recording;    // after Finish of a collecting parser, or Restore
  bool restored = false;           // Restore: the summary and log_recording were handed in

  Status FeedAny(std::string_view chunk);
  Status FinishAny();
  Status EndSniff();
  Status FinishLog();
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_RECORDING_PARSER_H_
