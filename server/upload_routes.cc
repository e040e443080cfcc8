// POST /api/v1/recordings and POST /api/v1/jobs (server/service_impl.h).
#include "server/service_impl.h"
#include "methods/registry.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// A staged upload file, removed when this goes out of scope.
class StagingFile {
 public:
  StagingFile() = default;
  ~StagingFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!path_.empty()) ::unlink(path_.c_str());
  }
  Status Create(const fs::path& dir) {
    std::string tmpl = (dir / "upload-XXXXXX").string();
    fd_ = ::mkstemp(tmpl.data());
    if (fd_ < 0) return Status::IoError("cannot create a staging file in " + dir.string());
    path_ = tmpl;
    return Status::Ok();
  }
  bool Write(const char* data, size_t len) {
    while (len > 0) {
      const ssize_t n = ::write(fd_, data, len);
      if (n < 0) {
        if (errno == EINTR) continue;
        errno_ = errno;
        return false;
      }
      data += n;
      len -= static_cast<size_t>(n);
    }
    return true;
  }
  Status Close() {
    if (fd_ >= 0 && ::close(fd_) != 0) {
      errno_ = errno;
      fd_ = -1;
      return WriteError();
    }
    fd_ = -1;
    return Status::Ok();
  }
  // Why the last Write or Close failed: a full disk (or quota) is 507 with reason disk_full.
  Status WriteError() const {
    if (errno_ == ENOSPC || errno_ == EDQUOT) {
      return Status::IoError(
                 "cannot write the upload to disk: the disk holding the staging "
                 "folder is full (" +
                 std::string(std::strerror(errno_)) + ")")
          .WithReason(Reason::kDiskFull);
    }
    return Status::IoError("cannot write the upload to disk: " +
                           std::string(std::strerror(errno_)));
  }
  const std::string& path() const { return path_; }

 private:
  int errno_ = 0;  // of the last failed write
  int fd_ = -1;
  std::string path_;
};

}  // namespace

bool IsGzipEncoding(const std::string& encoding) {
  const std::string e = ToLower(encoding);
  return e == "gzip" || e == "x-gzip";
}

// The config's references to other jobs, resolved by its method before the job is stored
// (Method::ResolveReferences). A config without a known method is left as is: ValidateConfig then
// names what is wrong with it.
Status ResolveJobReferences(storage::Store* store, json* config) {
  if (!config->is_object()) return Status::Ok();
  const auto m = config->find("method");
  if (m == config->end() || !m->is_string()) return Status::Ok();
  const Method* method = FindMethod(m->get_ref<const std::string&>());
  return method == nullptr ? Status::Ok() : method->ResolveReferences(store, config);
}

void Service::Impl::HandleUpload(const httplib::Request& req, httplib::Response& res,
                                 const httplib::ContentReader& reader) {
  int64_t received = 0;
  auto finish = [&](int status) { metrics.ObserveUpload(received, status); };

  // Config from the query string (text/csv bodies) — validated before the body is read.
  json config;
  Status s = ConfigFromQuery(req.params, &config);
  if (!s.ok()) return finish(SendStatus(res, s));

  const std::string content_type = req.get_header_value("Content-Type");
  const std::string media = ToLower(content_type.substr(0, content_type.find(';')));
  const bool multipart = req.is_multipart_form_data();
  const bool body_gzip = IsGzipEncoding(req.get_header_value(kBodyEncodingHeader));
  if (multipart && body_gzip) {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "a gzip-compressed multipart body is not accepted; compress the 'recording' part "
              "instead (a .csv.gz file)");
    return finish(415);
  }
  if (!multipart && media != "text/csv" && media != "text/plain" && media != "application/csv" &&
      media != "application/octet-stream" && media != "application/gzip" &&
      media != "application/x-gzip") {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "send the recording as text/csv, or as multipart/form-data with parts 'recording' "
              "and 'config'; not '" +
                  content_type.substr(0, 64) + "'");
    return finish(415);
  }

  StagingFile staged;
  s = staged.Create(staging_dir);
  if (!s.ok()) return finish(SendStatus(res, s));
  Sha256 sha;
  RecordingParser parser("upload", /*collect=*/false);
  Status parse_status;  // first CSV error
  Status body_status;   // first other error (size, I/O, multipart shape)
  std::string file_name;

  // The recording may be gzip-compressed (Content-Encoding: gzip, or a body or part that starts
  // with the gzip magic bytes, e.g. a .csv.gz file). It is decompressed as it arrives, and the
  // decompressed CSV is what is parsed, hashed and stored: the same log sent compressed or not
  // is one recording, and GET /recordings/{id}/data returns the CSV.
  GzipLimits gzip_limits;
  gzip_limits.max_output_bytes = options.max_upload_bytes;
  gzip_limits.max_ratio = options.max_gzip_ratio;
  std::unique_ptr<GzipInflater> inflater;  // set when the recording is compressed
  std::string head;                        // the first bytes, until the magic can be seen
  bool decided = false;                    // compressed or not is known
  int64_t csv_bytes = 0;

  auto take_csv_bytes = [&](const char* data, size_t len) {
    csv_bytes += static_cast<int64_t>(len);
    if (csv_bytes > options.max_upload_bytes) {
      body_status =
          Status(StatusCode::kTooLarge, "the recording is larger than the limit of " +
                                            std::to_string(options.max_upload_bytes) + " bytes");
      return false;
    }
    sha.Update(std::string_view(data, len));
    if (!staged.Write(data, len)) {
      body_status = staged.WriteError();
      return false;
    }
    parse_status = parser.Feed(std::string_view(data, len));
    return parse_status.ok();
  };
  auto feed_recording = [&](const char* data, size_t len) {
    if (!inflater) return take_csv_bytes(data, len);
    Status st = inflater->Feed(data, len, take_csv_bytes);
    if (!st.ok() && !GzipInflater::IsSinkStopped(st)) body_status = st;
    return st.ok();
  };
  auto take_recording_bytes = [&](const char* data, size_t len) {
    received += static_cast<int64_t>(len);
    if (received > options.max_upload_bytes) {
      body_status =
          Status(StatusCode::kTooLarge, "the upload is larger than the limit of " +
                                            std::to_string(options.max_upload_bytes) + " bytes");
      return false;
    }
    if (!decided) {
      const size_t take = std::min(len, 2 - head.size());
      head.append(data, take);
      data += take;
      len -= take;
      if (head.size() < 2 && !body_gzip) return true;
      decided = true;
      if (body_gzip || LooksLikeGzip(head.data(), head.size())) {
        inflater = std::make_unique<GzipInflater>(gzip_limits, "the recording");
      }
      if (!feed_recording(head.data(), head.size())) return false;
    }
    return len == 0 || feed_recording(data, len);
  };
  // After the last byte: a recording of one byte, and the end of a gzip stream.
  auto end_recording = [&] {
    if (!decided && !head.empty()) {
      decided = true;
      if (!feed_recording(head.data(), head.size())) return;
    }
    if (inflater) {
      Status st = inflater->Finish();
      if (!st.ok()) body_status = st;
    }
  };

  bool read_ok;
  if (multipart) {
    std::string part;  // name of the current part
    std::string config_text;
    bool have_recording = false, have_config = false;
    read_ok = reader(
        [&](const httplib::MultipartFormData& header) {
          part = header.name;
          if (part == "recording") {
            if (have_recording) {
              body_status =
                  Status::InvalidInput("more than one 'recording' part").WithField("recording");
              return false;
            }
            have_recording = true;
            file_name = header.filename;
          } else if (part == "config") {
            if (have_config) {
              body_status = Status::InvalidInput("more than one 'config' part").WithField("config");
              return false;
            }
            have_config = true;
          } else {
            body_status = Status::InvalidInput("unknown multipart part '" + part.substr(0, 64) +
                                               "': expected 'recording' and 'config'")
                              .WithField(part.substr(0, 64));
            return false;
          }
          return true;
        },
        [&](const char* data, size_t len) {
          if (part == "recording") return take_recording_bytes(data, len);
          received += static_cast<int64_t>(len);
          if (static_cast<int64_t>(config_text.size() + len) > options.max_json_body_bytes) {
            body_status = Status(StatusCode::kTooLarge,
                                 "the config part is larger than " +
                                     std::to_string(options.max_json_body_bytes) + " bytes");
            return false;
          }
          config_text.append(data, len);
          return true;
        });
    if (read_ok && body_status.ok() && parse_status.ok()) {
      if (!have_recording) {
        body_status = Status::InvalidInput("no 'recording' part in the multipart body")
                          .WithField("recording");
      } else if (have_config) {
        json part_config;
        Status cs = ParseJsonText(config_text, "config", &part_config);
        if (!cs.ok()) {
          body_status = cs.WithField("config");
        } else if (!part_config.is_object()) {
          body_status =
              Status::InvalidInput("the config part must be a JSON object").WithField("config");
        } else {
          for (auto& [key, value] : part_config.items()) {
            if (config.contains(key)) {
              body_status = Status::InvalidInput("key '" + key +
                                                 "' given both in the query and the config part")
                                .WithField(key);
              break;
            }
            config[key] = value;
          }
        }
      }
    }
  } else {
    read_ok = reader([&](const char* data, size_t len) { return take_recording_bytes(data, len); });
  }
  if (read_ok && body_status.ok() && parse_status.ok()) end_recording();

  if (!body_status.ok()) {
    if (body_status.reason() == Reason::kDiskFull) health.Note(body_status, "an upload", true);
    res.set_header("Connection", "close");
    return finish(SendStatus(res, body_status));
  }
  if (!parse_status.ok()) {
    res.set_header("Connection", "close");
    return finish(SendStatus(res, parse_status));
  }
  if (!read_ok) {
    // The connection broke or the body was malformed (e.g. bad chunk sizes, truncated multipart).
    res.set_header("Connection", "close");
    SendError(res, 400, "invalid_input", "the request body could not be read completely");
    return finish(400);
  }
  s = parser.Finish();
  if (!s.ok()) return finish(SendStatus(res, s));
  const RecordingSummary& summary = parser.summary();

  storage::NewRecording rec;
  rec.path = staged.path();
  rec.sha256 = sha.HexDigest();
  rec.layout = LayoutName(summary.layout);
  rec.rows = summary.rows;
  rec.columns_json = json(summary.columns).dump();
  rec.sensors_json = json(summary.sensors).dump();
  rec.file_name = file_name;
  CommonConfig common;
  const bool has_method = config.contains("method");
  if (has_method) {
    s = ResolveJobReferences(store.get(), &config);
    if (!s.ok()) return finish(SendStatus(res, s));
    s = ValidateConfig(config, &common);
    if (!s.ok()) return finish(SendStatus(res, s));
    if (!common.device.empty()) config["device"] = common.device;  // the stored (NFC) serial
    s = CheckJobSeconds(common, static_cast<double>(job_seconds));
    if (!s.ok()) return finish(SendStatus(res, s));
    const Method& method = *FindMethod(common.method);
    TimeUnit time_unit = TimeUnit::kSeconds;
    bool time_unit_given = false;
    s = ParseTimeUnit(config, &time_unit, &time_unit_given);  // validated above
    if (!s.ok()) return finish(SendStatus(res, s));
    if (method.NeedsIncreasingTime()) {  // raw-log methods
      s = CheckTimesIncrease(summary, common.method, time_unit);
      if (!s.ok()) return finish(SendStatus(res, s));
    }
    if (!method.Reads(summary.layout)) {
      return finish(SendStatus(res, Status::InvalidInput(std::string("method '") + common.method +
                                                         "' cannot read the recording's " +
                                                         LayoutName(summary.layout) + " layout")
                                        .WithField("method")));
    }
    // A time column in ms or ns read as seconds would make the job compute for hours on a
    // nonsense rate: refused now, nothing stored (the summary's figures are in the file's unit,
    // whatever unit the config names; the worker checks the same for jobs on stored logs).
    if (!time_unit_given && method.ReadsTime(WithoutAcceptance(config))) {
      s = CheckTimeUnit(summary, file_name.empty() ? "upload" : file_name);
      if (!s.ok()) return finish(SendStatus(res, s));
    }
    const RecordingShape shape{summary.rows, static_cast<int64_t>(summary.columns.size())};
    s = CheckJobBudget(*FindMethod(common.method), shape, WithoutAcceptance(config),
                       job_memory_bytes);
    if (!s.ok()) return finish(SendStatus(res, s));
    rec.job = storage::NewJob{common.method, common.device,
                              config.dump(-1, ' ', false, json::error_handler_t::replace)};
  } else if (config.contains("device")) {
    if (!config["device"].is_string()) {
      return finish(
          SendStatus(res, Status::InvalidInput("'device' must be a string").WithField("device")));
    }
    s = NormalizeSerial(config["device"].get_ref<const std::string&>(), &common.device);
    if (!s.ok()) return finish(SendStatus(res, s));
    for (auto& [key, value] : config.items()) {
      if (key != "device") {
        return finish(
            SendStatus(res, Status::InvalidInput("config key '" + key + "' given without 'method'")
                                .WithField(key)));
      }
    }
  }
  rec.device = common.device;
  s = staged.Close();
  if (!s.ok()) return finish(SendStatus(res, s));

  storage::RecordingInfo info;
  bool existed = false;
  s = store->PutRecording(rec, &info, &existed);
  // A stored upload is a sound write (the disk is not full) and repairs a damaged copy of the
  // same bytes (Store::PutRecording).
  health.Note(s, s.ok() ? "recording " + std::to_string(info.id) : "an upload", true);
  if (!s.ok()) return finish(SendStatus(res, s));
  json body = {{"recording",
                {{"id", info.id},
                 {"sha256", info.sha256},
                 {"bytes", info.bytes},
                 {"rows", info.rows},
                 {"layout", info.layout},
                 {"existed", existed},
                 {"compressed_bytes", inflater ? json(inflater->compressed_bytes()) : json()},
                 {"url", "/api/v1/recordings/" + std::to_string(info.id)}}}};
  if (info.job) {
    body["job"] = {{"id", info.job->id},
                   {"status", info.job->status},
                   {"url", "/api/v1/jobs/" + std::to_string(info.job->id)},
                   {"report_url", "/jobs/" + std::to_string(info.job->id)}};
    res.set_header("Location", "/api/v1/jobs/" + std::to_string(info.job->id));
    workers->Notify();
  } else {
    res.set_header("Location", "/api/v1/recordings/" + std::to_string(info.id));
  }
  res.status = 201;
  res.set_content(JsonBody(body), "application/json");
  finish(201);
}

void Service::Impl::HandleCreateJob(const httplib::Request& req, httplib::Response& res) {
  const std::string media = ToLower(req.get_header_value("Content-Type"));
  if (media.rfind("application/json", 0) != 0) {
    SendError(res, 415, "unsupported_media_type", "send the job as application/json");
    return;
  }
  json body;
  Status s = ParseJsonText(req.body, "request body", &body);
  if (!s.ok()) return (void)SendStatus(res, s);
  if (!body.is_object()) {
    SendError(res, 400, "invalid_input", "the body must be a JSON object");
    return;
  }
  for (auto& [key, value] : body.items()) {
    if (key != "recording_id" && key != "config") {
      return (void)SendStatus(
          res, Status::InvalidInput("unknown key '" + key + "' (expected recording_id, config)")
                   .WithField(key));
    }
  }
  if (!body.contains("recording_id") || !body["recording_id"].is_number_integer()) {
    return (void)SendStatus(
        res, Status::InvalidInput("'recording_id' must be an integer").WithField("recording_id"));
  }
  if (!body.contains("config")) {
    return (void)SendStatus(res, Status::InvalidInput("missing 'config'").WithField("config"));
  }
  const int64_t recording_id = body["recording_id"].get<int64_t>();
  json& config = body["config"];
  s = ResolveJobReferences(store.get(), &config);
  if (!s.ok()) return (void)SendStatus(res, s);
  CommonConfig common;
  s = ValidateConfig(config, &common);
  if (!s.ok()) return (void)SendStatus(res, s);
  if (!common.device.empty()) config["device"] = common.device;  // the stored (NFC) serial
  s = CheckJobSeconds(common, static_cast<double>(job_seconds));
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::RecordingInfo recording;
  s = store->GetRecording(recording_id, &recording);
  if (!s.ok()) return (void)SendStatus(res, s);
  Layout layout;
  if (!LayoutFromName(recording.layout, &layout) || !FindMethod(common.method)->Reads(layout)) {
    return (void)SendStatus(
        res,
        Status::InvalidInput("method '" + common.method + "' cannot read recording " +
                             std::to_string(recording_id) + "'s " + recording.layout + " layout")
            .WithField("method"));
  }
  const json columns = json::parse(recording.columns_json, nullptr, /*allow_exceptions=*/false);
  const RecordingShape shape{recording.rows,
                             columns.is_array() ? static_cast<int64_t>(columns.size()) : 0};
  s = CheckJobBudget(*FindMethod(common.method), shape, WithoutAcceptance(config),
                     job_memory_bytes);
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::JobInfo job;
  s = store->EnqueueJob(recording_id, common.method, common.device,
                        config.dump(-1, ' ', false, json::error_handler_t::replace), &job);
  if (!s.ok()) return (void)SendStatus(res, s);
  workers->Notify();
  res.status = 202;
  res.set_header("Location", "/api/v1/jobs/" + std::to_string(job.id));
  res.set_content(JsonBody(json{{"job", JobJson(job, false)}}), "application/json");
}

}  // namespace calibd::server
