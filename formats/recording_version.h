// The version of RecordingParser's reading rules (formats/recording.h).
#ifndef CALIBD_FORMATS_RECORDING_VERSION_H_
#define CALIBD_FORMATS_RECORDING_VERSION_H_

namespace calibd::server {

// The reading rules of RecordingParser and every reader it uses (formats/: the CSV path in
// recording*.cc and csv_dialect.cc, the sensor log readers and log_assembly.cc): bump it in the
// same change as any edit that can give other numbers, names or summary for the same bytes and
// settings (a parse fixed, a unit or rounding changed, a stream read otherwise). It is part of
// the parsed-columns cache's key (server/column_cache.h RulesText), so entries parsed under the
// old rules are never served after the change.
inline constexpr int kRecordingParserVersion = 1;

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_RECORDING_VERSION_H_
