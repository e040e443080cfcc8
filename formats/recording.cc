// Recordings (formats/recording.h): the names of layouts and time units, and RecordingParser,
// whose stages are in recording_fields.cc and recording_rows.cc (formats/recording_parser.h).
#include "formats/recording.h"

#include <string>
#include <utility>

#include "formats/recording_parser.h"

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

Status RecordingParser::Feed(std::string_view chunk) { return impl_->FeedAny(chunk); }
Status RecordingParser::Finish() { return impl_->FinishAny(); }
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
  if (d.log_format != LogFormat::kUnknown || d.restored) {
    *out = std::move(d.log_recording);
    return Status::Ok();
  }
  d.HandOverArray(&d.direct_accel, &d.direct_gyro, &d.array_values, out);
  return Status::Ok();
}

void RecordingParser::CollectArrayAsFloat(double accel_scale, double gyro_scale) {
  if (impl_->have_header) return;  // too late: the numbers are already held as double
  impl_->as_float = true;
  impl_->float_scale_accel = accel_scale;
  impl_->float_scale_gyro = gyro_scale;
}

void RecordingParser::CollectArrayAsDouble() {
  if (impl_->have_header) return;
  impl_->as_float = false;
  impl_->float_scale_accel = impl_->float_scale_gyro = 1;
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

void RecordingParser::SetCsvDialect(const CsvDialect& dialect) {
  if (impl_->have_header) return;  // too late: the header was read with the old one
  impl_->dialect = dialect;
}

bool RecordingParser::header_read() const { return impl_->header_ok; }

const CsvDialect& RecordingParser::csv_dialect() const { return impl_->dialect; }

const LogStreamSelection& RecordingParser::log_streams() const { return impl_->log_streams; }

bool RecordingParser::collects() const { return impl_->collect; }

void RecordingParser::Restore(const RecordingSummary& summary, ArrayRecording log) {
  Impl& d = *impl_;
  d.summary = summary;
  d.summary.time_unit = d.time_unit;
  d.log_recording = std::move(log);
  d.restored = true;
  d.finished = true;
  d.error = Status::Ok();
  // What the CSV stages held is released: the recording is the one handed in.
  d.array_values = {};
  d.t_values = {};
  d.side_values = {};
  d.array_values_f = {};
  d.direct = false;
  d.direct_accel.resize(0, 0);
  d.direct_gyro.resize(0, 0);
  d.direct_t.resize(0);
  d.direct_side.resize(0, 0);
  d.direct_accel_f.resize(0, 0);
  d.direct_gyro_f.resize(0, 0);
  d.log_bytes = {};
}

void RecordingParser::SetLogStreams(const LogStreamSelection& streams) {
  const bool mag = impl_->log_streams.mag_time_base;
  impl_->log_streams = streams;
  impl_->log_streams.mag_time_base = mag;
}

void RecordingParser::SetLogTimeBaseMag() { impl_->log_streams.mag_time_base = true; }

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
  if (d.log_format != LogFormat::kUnknown || d.restored) {
    ArrayRecording& r = d.log_recording;
    out->accel_names = std::move(r.accel_names);
    out->gyro_names = std::move(r.gyro_names);
    out->accel = (r.accel * d.float_scale_accel).cast<float>();
    out->gyro = (r.gyro * d.float_scale_gyro).cast<float>();
    out->t = std::move(r.t);
    out->temp_names = std::move(r.temp_names);
    out->temperature = std::move(r.temperature);
    out->mag_names = std::move(r.mag_names);
    out->mag = std::move(r.mag);
    out->mag_device_ids = std::move(r.mag_device_ids);
    r = {};
    return Status::Ok();
  }
  d.HandOverArray(&d.direct_accel_f, &d.direct_gyro_f, &d.array_values_f, out);
  return Status::Ok();
}

Status ParseRecording(std::string_view bytes, RecordingParser* parser) {
  Status s = parser->Feed(bytes);
  if (!s.ok()) return s;
  return parser->Finish();
}

}  // namespace calibd::server
