// The recording parser's binary sensor logs (RecordingParser::Impl, formats/recording_parser.h):
// recognition by the first bytes, then the whole log read at Finish and assembled into the
// array recording the methods read, with a summary as for the equivalent CSV.
#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "formats/log_readers.h"
#include "formats/recording_parser.h"

namespace calibd::server {

Status RecordingParser::Impl::FeedAny(std::string_view chunk) {
  if (!error.ok()) return error;
  if (sniffed) {
    if (log_format == LogFormat::kUnknown) return Feed(chunk);
    if (static_cast<int64_t>(log_bytes.size() + chunk.size()) > limits.max_log_bytes) {
      error =
          Status::InvalidInput("the log is larger than " + std::to_string(limits.max_log_bytes) +
                               " bytes, this server's limit for a sensor log")
              .WithFile(file_name);
      return error;
    }
    log_bytes.append(chunk);
    return Status::Ok();
  }
  const size_t want = kSniffBytes - head.size();
  head.append(chunk.substr(0, want));
  if (head.size() < kSniffBytes) return Status::Ok();
  Status s = EndSniff();
  if (!s.ok() || chunk.size() <= want) return s;
  return FeedAny(chunk.substr(want));
}

Status RecordingParser::Impl::EndSniff() {
  sniffed = true;
  log_format = SniffLogFormat(head);
  std::string first = std::move(head);
  head.clear();
  if (log_format == LogFormat::kUnknown) return Feed(first);
  summary.format = LogFormatName(log_format);
  log_bytes = std::move(first);
  return Status::Ok();
}

Status RecordingParser::Impl::FinishAny() {
  if (!error.ok()) return error;
  if (!sniffed) {
    Status s = EndSniff();
    if (!s.ok()) return s;
  }
  if (log_format == LogFormat::kUnknown) return Finish();
  if (finished) return Status::Internal("Finish called twice");
  Status s = FinishLog();
  if (!s.ok()) {
    error = s;
    return s;
  }
  finished = true;
  return Status::Ok();
}

Status RecordingParser::Impl::FinishLog() {
  SensorLog log;
  SensorLogLimits log_limits;
  Status s = ReadSensorLog(log_format, log_bytes, file_name, log_limits, &log);
  std::string().swap(log_bytes);  // the samples are read: the bytes go
  if (!s.ok()) return s;
  AssembledLog assembled;
  s = AssembleLog(log, log_streams, file_name, &assembled);
  if (!s.ok()) return s;
  log = {};
  const ArrayRecording& r = assembled.recording;
  summary.layout = Layout::kArray;
  summary.rows = r.t.size();
  summary.columns = {"t"};
  summary.sensors.clear();
  for (const std::string& a : r.accel_names) {
    for (const char* axis : {"_x", "_y", "_z"}) summary.columns.push_back(a + axis);
    summary.sensors.push_back(a);
  }
  for (const std::string& g : r.gyro_names) {
    for (const char* axis : {"_x", "_y", "_z"}) summary.columns.push_back(g + axis);
    summary.sensors.push_back(g);
  }
  for (const std::string& m : r.mag_names) {
    for (const char* axis : {"_x", "_y", "_z"}) summary.columns.push_back(m + axis);
    summary.sensors.push_back(m);
  }
  for (const std::string& c : r.temp_names) summary.columns.push_back(c);
  summary.t_column = 1;
  summary.t_first_line = 0;
  summary.t_first = r.t(0);
  std::vector<double> steps;
  const Eigen::Index probe = std::min<Eigen::Index>(r.t.size(), kTimeProbeRows);
  for (Eigen::Index i = 1; i < probe; ++i) steps.push_back(r.t(i) - r.t(i - 1));
  if (!steps.empty()) {
    std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
    summary.t_median_step = steps[steps.size() / 2];
  }
  summary.time_origin = assembled.time_origin;
  summary.time_unit = TimeUnit::kSeconds;
  summary.log_description = assembled.description.dump();
  if (collect) log_recording = std::move(assembled.recording);
  return Status::Ok();
}

}  // namespace calibd::server
