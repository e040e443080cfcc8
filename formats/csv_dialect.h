// CSV files from other tools (SPEC §9 "CSV from other tools"; issue 30 / #24): config `columns`
// maps calibd's column names to the file's header names, `delimiter` and `decimal` say how its
// fields and numbers are written. The recording parser applies them (RecordingParser::
// SetCsvDialect); this header reads and checks the config keys and names calibd's columns.
#ifndef CALIBD_FORMATS_CSV_DIALECT_H_
#define CALIBD_FORMATS_CSV_DIALECT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "base/status.h"

namespace calibd::server {

// How a CSV is read. The default reads calibd's own files (SPEC §2). Plain data, copyable.
struct CsvDialect {
  // calibd name → the file's header name ("a0_x" → "accX"), in config order; empty: the header
  // names are calibd's. No two entries name one file column (ParseCsvDialect refuses it).
  std::vector<std::pair<std::string, std::string>> columns;
  char delimiter = ',';  // ',', ';' or '\t'
  char decimal = '.';    // '.' or ','; ',' only with a delimiter other than ','

  bool IsDefault() const { return columns.empty() && delimiter == ',' && decimal == '.'; }
  // {"columns": {calibd name: file name}, "delimiter": ";", "decimal": ","}: as the config
  // writes them (a tab as "\t"), for the recording JSON and for a job's config.
  nlohmann::json ToJson() const;
};

// The config keys ParseCsvDialect reads.
inline constexpr const char* kCsvDialectKeys[] = {"columns", "delimiter", "decimal"};
bool HasCsvDialectKeys(const nlohmann::json& config);

// Reads config `columns`, `delimiter` and `decimal` (absent: the default). kInvalidInput naming
// the key (`columns.<key>` for an entry): `columns` not an object, a key that is not a calibd
// column name (IsCalibdColumnName), a value that is not a non-empty printable string, two keys
// naming one file column (both named); a delimiter other than ",", ";", "\t" (or "tab"); a
// decimal other than "." or ","; decimal "," with delimiter "," (both named).
Status ParseCsvDialect(const nlohmann::json& config, CsvDialect* dialect);

// `temp` or `tempK` (K a triad index without leading zeros): a temperature column (SPEC §8).
bool IsTemperatureColumn(std::string_view name);
// "a12_x" style names: kind 'a' (accelerometer), 'g' (gyroscope) or 'm' (magnetometer), triad
// index (no leading zeros) and axis 0..2; false for any other form.
bool ParseTriadColumn(std::string_view name, char* kind, int* index, int* axis);
// A column name of the array layout: t, aK_*, gK_*, mK_*, temp, tempK.
bool IsArrayColumnName(std::string_view name);
// A name config `columns` may map: the array layout's, and the pca layout's position, phase.
bool IsCalibdColumnName(std::string_view name);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_CSV_DIALECT_H_
