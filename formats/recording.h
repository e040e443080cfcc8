// Recordings: the CSV formats of SPEC §2, parsed strictly and incrementally.
//
// RecordingParser takes the bytes in chunks of any size (so an upload can be validated while it
// streams, without holding it in memory) and either only validates and summarises them, or also
// collects the numbers for a calibration. Every error names the file, the 1-based line and column,
// and the column's header name where one applies.
#ifndef CALIBD_SERVER_RECORDING_H_
#define CALIBD_SERVER_RECORDING_H_

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "base/utf8.h"

namespace calibd::server {

struct LogStreamSelection;  // formats/log_assembly.h
struct CsvDialect;          // formats/csv_dialect.h

enum class Layout {
  kPcaAveraged,  // position,s1,...,sm
  kPcaRaw,       // position,phase,s1,...,sm   (phase: static | moving)
  kArray,        // [t,]aK_x,aK_y,aK_z,...,gJ_x,gJ_y,gJ_z,mJ_x,..  (any column order)
};
const char* LayoutName(Layout layout);  // pca_averaged, pca_raw, array (stored, SPEC §2)

// The unit of an array recording's time column `t` (config `time_unit`, SPEC §9): seconds are
// the value divided by 10^digits.
enum class TimeUnit { kSeconds, kMilliseconds, kMicroseconds, kNanoseconds };
const char* TimeUnitName(TimeUnit unit);  // "s", "ms", "us", "ns"
// The inverse of TimeUnitName; false for anything else.
bool TimeUnitFromName(std::string_view name, TimeUnit* unit);
int TimeUnitDigits(TimeUnit unit);  // 0, 3, 6, 9
// The inverse of LayoutName; false for an unknown name.
bool LayoutFromName(std::string_view name, Layout* layout);

// A pca recording reduced to one column per position.
struct PcaRecording {
  std::vector<std::string> sensor_names;     // m names, header order
  std::vector<std::string> position_labels;  // n labels, in order of first appearance
  // m×n. Averaged layout: the mean of the rows with that label (usually one row each).
  // Raw layout: mean of the position's `moving` rows minus the mean of its `static` rows
  // (the paper's Eq. 18, m = m′ − b′).
  Eigen::MatrixXd readings;
  bool raw = false;
  // Raw layout only (else empty): m×n means of the static rows, b′ per position, and the number
  // of static and moving rows per position.
  Eigen::MatrixXd static_means;
  std::vector<int64_t> static_rows, moving_rows;
  std::vector<int64_t> rows_per_position;  // n: rows that went into each column (both layouts)
};

// An array recording: one row per sample.
struct ArrayRecording {
  std::vector<std::string> accel_names;  // "a0".."a{K-1}", by index
  std::vector<std::string> gyro_names;   // "g0".."g{G-1}", by index
  Eigen::MatrixXd accel;                 // N × 3K: a0_x a0_y a0_z a1_x ... (m/s²)
  Eigen::MatrixXd gyro;                  // N × 3G: g0_x g0_y g0_z ... (unit as recorded)
  // N seconds (the `t` column in the parser's time unit converted to seconds, counted from
  // RecordingSummary::time_origin), or empty when there is no `t` column.
  Eigen::VectorXd t;
  // Temperature columns (°C, SPEC §8): `temp` (one for all IMUs) and/or `tempK` (IMU K), in
  // file order, N × their number; empty when the log has none. Methods that do not use
  // temperature ignore them.
  std::vector<std::string> temp_names;
  Eigen::MatrixXd temperature;
  // Magnetometer triads `mK_x,mK_y,mK_z` (SPEC §8 mag): N × 3M, reading units as recorded (always
  // double); empty when the log has none. Methods that do not use them ignore them.
  std::vector<std::string> mag_names;  // "m0".., by index
  Eigen::MatrixXd mag;
  // Per magnetometer, the firmware's device id its log stream carries (ULog sensor_mag's
  // device_id, DataFlash COMPASS_DEV_ID*), -1 where it has none; empty for a CSV recording.
  std::vector<int64_t> mag_device_ids;
};

// An array recording held as floats (RecordingParser::CollectArrayAsFloat): what the raw-log
// methods analyse, at half the memory of ArrayRecording. Each value is the reading times the
// scale of its kind, computed in double and rounded once to float; t stays double (a float has
// 0.5 ms resolution at t = 2 h, too coarse for the sample period and its jitter).
struct ArrayRecordingFloat {
  std::vector<std::string> accel_names;  // "a0".."a{K-1}", by index
  std::vector<std::string> gyro_names;   // "g0".."g{G-1}", by index
  Eigen::MatrixXf accel;                 // N × 3K: a0_x a0_y a0_z a1_x ... times accel_scale
  Eigen::MatrixXf gyro;                  // N × 3G: g0_x ... times gyro_scale
  Eigen::VectorXd t;                     // as ArrayRecording::t
  std::vector<std::string> temp_names;   // as ArrayRecording (kept in double)
  Eigen::MatrixXd temperature;
  std::vector<std::string> mag_names;  // as ArrayRecording (kept in double, not scaled)
  Eigen::MatrixXd mag;
  std::vector<int64_t> mag_device_ids;  // as ArrayRecording
  double accel_scale = 1, gyro_scale = 1;
};

// What storage keeps about a recording without re-reading it.
struct RecordingSummary {
  Layout layout = Layout::kPcaAveraged;
  int64_t rows = 0;                  // data rows (comments and header excluded)
  std::vector<std::string> columns;  // header names in file order
  // pca: sensor names; array: triad names (a0.., then g0.., then m0..).
  std::vector<std::string> sensors;
  int64_t positions = 0;  // pca only: distinct position labels
  // array layout with `t`: the first row whose t is not greater than the previous row's (line
  // and column in the file; 0 when t increases strictly throughout). Not an error of the layout
  // (the array method accepts any t); the raw-log methods refuse it (CheckLogTimes). The values
  // as the file writes them (its unit, not converted).
  int64_t t_disorder_line = 0, t_disorder_column = 0;
  double t_disorder = 0, t_disorder_previous = 0;
  // array layout with `t`, for the time-unit plausibility check (formats/inertial_log.h
  // CheckTimeUnit), in the file's own unit whatever the parser's time unit: the first row's t
  // (its line; the column is t_column), and the median difference of consecutive t over the first
  // kTimeProbeRows rows (0 with fewer than 2 rows).
  int64_t t_column = 0;  // 1-based column of `t` (0: none)
  int64_t t_first_line = 0;
  double t_first = 0;
  double t_median_step = 0;
  // Whole seconds subtracted from every t before it became a double (0: none). Set when the first
  // stamp is at least kTimeOriginSeconds (epoch stamps): the stamps are read exactly (integer and
  // fraction digits apart) and counted from this whole second, so no precision is lost to a
  // double holding e.g. 1.7e18 ns. In the parser's time unit's clock (seconds).
  int64_t time_origin = 0;
  // The parser's time unit (RecordingParser::SetTimeUnit), for messages about t.
  TimeUnit time_unit = TimeUnit::kSeconds;
  // "csv", or the sensor log's format ("ulog", "dataflash", "rosbag1", "mcap", "rosbag2";
  // SPEC §9), whose units and time stamps its reader defines (config time_unit and the unit keys
  // are for CSV only). A log's rows are its first IMU's samples and its columns those of the
  // equivalent CSV (t, aK_*, gK_*, tempK).
  std::string format = "csv";
  // What was read, as JSON text: a log's AssembledLog::description; a CSV read with config
  // `columns`, `delimiter` or `decimal` (RecordingParser::SetCsvDialect): {"format": "csv",
  // "csv": {"columns": {calibd name: file name}, "delimiter", "decimal", "ignored": [file
  // columns not read]}, "warnings": [...]}; empty for a CSV read as calibd's own.
  std::string log_description;
};

// The rows whose time steps RecordingSummary::t_median_step is taken over (bounded work: the
// check is the same cost for any log size).
inline constexpr int64_t kTimeProbeRows = 4096;
// A first time stamp at least this many seconds from 0 makes the parser count the times from its
// whole second (RecordingSummary::time_origin). Logs starting nearer 0 are read exactly as
// before (the value parsed as a double, divided by 10^digits of the unit).
inline constexpr double kTimeOriginSeconds = 1e6;

struct RecordingLimits {
  int64_t max_line_bytes = 1 << 20;  // a longer line is an error (guards memory)
  int64_t max_columns = 4096;        // more header fields is an error
  // pca: more distinct position labels is an error (bounds the parser's memory: ~200 B each).
  int64_t max_positions = 200000;
  // Not a limit: read plain rows (numbers after single commas, no spaces or quotes) in one pass.
  // false sends every row through the general path; the outcome is identical either way (the
  // tests and the fuzz_recording target compare the two), only slower.
  bool one_pass_rows = true;
  // A binary sensor log (SPEC §9) is held whole until it is read: more bytes is an error.
  int64_t max_log_bytes = int64_t{4} << 30;
};

class RecordingParser {
 public:
  // file_name: used in error messages only. collect: also keep the numbers (Take*()).
  RecordingParser(std::string file_name, bool collect, RecordingLimits limits = {});
  ~RecordingParser();
  RecordingParser(const RecordingParser&) = delete;
  RecordingParser& operator=(const RecordingParser&) = delete;

  // Feed the next chunk. After the first error every call returns it again. The first bytes
  // decide the format: calibd's CSV, or a binary sensor log (formats/sensor_log.h), which is
  // held whole and read at Finish.
  Status Feed(std::string_view chunk);
  // Optional, before the first Feed of a collecting parser: the number of data rows the input
  // has (e.g. a stored recording's row count). An array recording's numbers then go straight
  // into the matrices TakeArray hands out: held once, instead of a growing row-major buffer
  // (up to 2x slack) plus the matrices copied from it. A wrong hint changes nothing but memory.
  void ExpectRows(int64_t rows);
  // Optional, before the first Feed of a collecting parser: keep an array recording's numbers as
  // float (4 bytes a value instead of 8), each multiplied by the scale of its kind in double
  // before the one rounding to float; TakeArrayFloat then hands them out (TakeArray refuses).
  // Does nothing to a pca recording, nor once the header has been read (collects_float() then
  // stays false).
  void CollectArrayAsFloat(double accel_scale, double gyro_scale);
  // Undoes CollectArrayAsFloat (a reader that needs the doubles, e.g. the check, after
  // PrepareParser); does nothing once the header has been read.
  void CollectArrayAsDouble();
  // Whether CollectArrayAsFloat was called, and with which scales (either pointer may be null).
  bool collects_float(double* accel_scale = nullptr, double* gyro_scale = nullptr) const;
  // Optional, before the first Feed: the unit of the time column (default seconds). The
  // collected t (ArrayRecording::t) is then in seconds: the value with its decimal point moved,
  // correctly rounded (a log in ms gives bit for bit the times of the same log in s). Does
  // nothing once the header has been read.
  void SetTimeUnit(TimeUnit unit);
  TimeUnit time_unit() const;
  // Optional, before the first Feed: how a CSV from another tool is read (config `columns`,
  // `delimiter`, `decimal`; formats/csv_dialect.h). With a mapping, the header's mapped names
  // read as their calibd names; in the array layout a header column neither mapped nor named as
  // calibd's is ignored (listed in the summary's warnings); a mapped name the header lacks, or a
  // mapping onto a calibd name another header column already has, is an error naming
  // `columns.<key>`. Does nothing to a sensor log, nor once the header has been read.
  void SetCsvDialect(const CsvDialect& dialect);
  // Whether a CSV's header line has been read without an error (false for a sensor log).
  bool header_read() const;
  // The reading rules in force (SetCsvDialect, SetLogStreams and SetLogTimeBaseMag): with
  // time_unit() and collects_float(), what decides the numbers a parse gives.
  const CsvDialect& csv_dialect() const;
  const LogStreamSelection& log_streams() const;
  bool collects() const;  // constructed with collect = true
  // A parse done before, handed in instead of Feed/Finish (a verified parsed-columns cache entry,
  // server/column_cache.h): the parser is then finished with this summary (its time_unit set to
  // the parser's) and this array recording, which TakeArray hands out as it is and
  // TakeArrayFloat converts as for a sensor log (reading × scale in double, rounded once to
  // float: the values a CSV parse collecting floats gives). The caller vouches that `log` is
  // what this parser, with its reading rules, made or would make of the recording; anything the
  // parser held is released.
  void Restore(const RecordingSummary& summary, ArrayRecording log);
  // Optional, before the first Feed: which streams of a binary sensor log form the IMUs (config
  // `streams`, SPEC §9; default every IMU). Does nothing to a CSV recording.
  void SetLogStreams(const LogStreamSelection& streams);
  // Optional, before Finish: a sensor log's time base is its first magnetometer's times (the mag
  // method; LogStreamSelection::mag_time_base). Kept by a later SetLogStreams.
  void SetLogTimeBaseMag();
  // End of input: checks the last line and the whole-file rules (e.g. every raw position has
  // static and moving rows). Must be called once after the last Feed.
  Status Finish();

  const RecordingSummary& summary() const;
  // Valid after a successful Finish() of a collecting parser, for the matching layout.
  Status TakePca(PcaRecording* out);
  Status TakeArray(ArrayRecording* out);
  Status TakeArrayFloat(ArrayRecordingFloat* out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Parses a plain decimal ("-12.5e-3") exactly as std::from_chars would, when it can do so by
// Clinger's fast path (<= 19 significant digits, mantissa <= 2^53, |exponent| <= 22); returns
// false, leaving *value alone, for everything else (the caller then uses std::from_chars).
bool ParseDecimalFast(std::string_view text, double* value);

// The same for the longest prefix of [p, end) shaped [-]digits[.digits][(e|E)[+|-]digits]:
// returns the end of that prefix, or nullptr (leaving *value alone) when there is no such prefix
// or it is outside the fast path. The recording parser's one-pass row reader is built on it.
const char* ParseDecimalPrefixFast(const char* p, const char* end, double* value);

using ::calibd::IsValidUtf8;  // base/utf8.h

// Convenience: parse a whole buffer (collecting).
Status ParseRecording(std::string_view bytes, RecordingParser* parser);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_RECORDING_H_
