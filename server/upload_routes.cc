// POST /api/v1/recordings and POST /api/v1/jobs (server/service_impl.h).
#include <fstream>

#include "formats/csv_dialect.h"
#include "formats/log_assembly.h"
#include "methods/registry.h"
#include "server/service_impl.h"

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

namespace {

// 415 for a body HandleUpload does not read: a gzip-compressed multipart body, or a media type
// that is neither CSV nor multipart. Returns the status sent, or 0 when the body is acceptable.
int RefuseUploadMedia(const httplib::Request& req, bool body_gzip, httplib::Response& res) {
  const std::string content_type = req.get_header_value("Content-Type");
  const std::string media = ToLower(content_type.substr(0, content_type.find(';')));
  const bool multipart = req.is_multipart_form_data();
  if (multipart && body_gzip) {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "a gzip-compressed multipart body is not accepted; compress the 'recording' part "
              "instead (a .csv.gz file)");
    return 415;
  }
  if (!multipart && media != "text/csv" && media != "text/plain" && media != "application/csv" &&
      media != "application/octet-stream" && media != "application/gzip" &&
      media != "application/x-gzip") {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "send the recording as text/csv, or as multipart/form-data with parts 'recording' "
              "and 'config'; not '" +
                  content_type.substr(0, 64) + "'");
    return 415;
  }
  return 0;
}

// An upload's body as it streams in. The recording may be gzip-compressed (Content-Encoding:
// gzip, or a body or part that starts with the gzip magic bytes, e.g. a .csv.gz file): it is
// decompressed as it arrives, and the decompressed CSV is what is parsed, hashed and staged on
// disk, chunk by chunk under the upload limits; the same log sent compressed or not is one
// recording, and GET /recordings/{id}/data returns the CSV. A multipart body's config part is
// merged into the query's config. How the CSV is read (config `columns`, `delimiter`,
// `decimal`) applies whatever the parts' order: a config part before the recording sets it
// before the first byte is parsed; after the recording, the staged file is parsed again with it
// (streamed from disk; a header the first reading refused is only staged meanwhile, and its
// error is answered when the config part does not name those keys). One per request; not
// thread-safe.
class UploadBody {
 public:
  // `options`: the upload limits (kept by reference: must outlive this); `body_gzip`: the
  // request's Content-Encoding is gzip.
  UploadBody(const ServeOptions& options, bool body_gzip)
      : options_(options),
        body_gzip_(body_gzip),
        parser_(std::make_unique<RecordingParser>("upload", /*collect=*/false)) {
    gzip_limits_.max_output_bytes = options.max_upload_bytes;
    gzip_limits_.max_ratio = options.max_gzip_ratio;
  }

  // Creates the staging file in `dir`.
  Status Stage(const fs::path& dir) { return staged_.Create(dir); }

  // Reads the whole body through `reader` (multipart: the parts 'recording' and 'config', whose
  // keys are added to *config; else the recording alone) and ends the recording when all went
  // well. false when the body could not be read completely (the connection broke, the body was
  // malformed, or a limit or error stopped it: body_status() or parse_status() then says why).
  bool Read(const httplib::ContentReader& reader, bool multipart, json* config) {
    bool read_ok;
    if (multipart) {
      multipart_ = true;
      query_config_ = config;
      read_ok = reader([&](const httplib::MultipartFormData& header) { return StartPart(header); },
                       [&](const char* data, size_t len) { return TakePartBytes(data, len); });
      if (read_ok && body_status_.ok() && parse_status_.ok()) MergeParts(config);
      if (read_ok && body_status_.ok() && parse_status_.ok()) ReadAfterConfig(*config);
    } else {
      read_ok = reader([&](const char* data, size_t len) { return TakeRecordingBytes(data, len); });
    }
    if (read_ok && body_status_.ok() && parse_status_.ok()) EndRecording();
    return read_ok;
  }

  int64_t received() const { return received_; }  // body bytes so far (as sent)
  // The first error other than the CSV's (size, I/O, gzip, multipart shape).
  const Status& body_status() const { return body_status_; }
  const Status& parse_status() const { return parse_status_; }  // the first CSV error
  RecordingParser& parser() { return *parser_; }
  StagingFile& staged() { return staged_; }
  // The recording's row as storage takes it, from the CSV read (after parser().Finish()).
  storage::NewRecording Recording() {
    const RecordingSummary& summary = parser_->summary();
    storage::NewRecording rec;
    rec.path = staged_.path();
    rec.sha256 = sha_.HexDigest();
    rec.layout = LayoutName(summary.layout);
    rec.rows = summary.rows;
    rec.columns_json = json(summary.columns).dump();
    rec.sensors_json = json(summary.sensors).dump();
    rec.log_json = summary.log_description;
    rec.file_name = file_name_;
    return rec;
  }
  const std::string& file_name() const { return file_name_; }  // the client's, or ""
  // The compressed size of a gzip'd recording; null when it was not compressed.
  json compressed_bytes() const { return inflater_ ? json(inflater_->compressed_bytes()) : json(); }

 private:
  // Decompressed (or plain) CSV bytes: counted against the limit, hashed, staged, parsed.
  bool TakeCsvBytes(const char* data, size_t len) {
    csv_bytes_ += static_cast<int64_t>(len);
    if (csv_bytes_ > options_.max_upload_bytes) {
      body_status_ =
          Status(StatusCode::kTooLarge, "the recording is larger than the limit of " +
                                            std::to_string(options_.max_upload_bytes) + " bytes");
      return false;
    }
    sha_.Update(std::string_view(data, len));
    if (!staged_.Write(data, len)) {
      body_status_ = staged_.WriteError();
      return false;
    }
    if (deferred_) return true;  // staged only: parsed again once the config part is known
    parse_status_ = parser_->Feed(std::string_view(data, len));
    if (!parse_status_.ok() && multipart_ && !have_config_ && !parser_->header_read()) {
      deferred_status_ = parse_status_;  // a config part after the recording may read it
      parse_status_ = Status::Ok();
      deferred_ = true;
    }
    return parse_status_.ok();
  }

  // After a multipart body whose config part came after the recording: the staged file parsed
  // again when that part names how the CSV is read; else the first reading's error stands.
  void ReadAfterConfig(const json& config) {
    if (!config_after_recording_ || !HasCsvDialectKeys(part_config_)) {
      if (deferred_) parse_status_ = deferred_status_;
      return;
    }
    CsvDialect dialect;
    parse_status_ = ParseCsvDialect(config, &dialect);
    if (!parse_status_.ok()) return;
    parser_ = std::make_unique<RecordingParser>("upload", /*collect=*/false);
    parser_->SetCsvDialect(dialect);
    std::ifstream in(staged_.path(), std::ios::binary);
    std::string buffer(1 << 16, '\0');
    while (in && parse_status_.ok()) {
      in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
      const std::streamsize got = in.gcount();
      if (got > 0) parse_status_ = parser_->Feed(std::string_view(buffer.data(), got));
    }
    if (in.bad()) body_status_ = Status::IoError("cannot read the staged upload back");
  }

  // A config part before the recording: its CSV keys (with the query's) set how it is read.
  bool ApplyEarlyConfig() {
    json merged = *query_config_;
    json part;
    Status s = ParseJsonText(config_text_, "config", &part);
    if (!s.ok() || !part.is_object()) return true;  // MergeParts names the problem
    if (!HasCsvDialectKeys(part)) return true;
    for (auto& [key, value] : part.items()) merged[key] = value;
    CsvDialect dialect;
    s = ParseCsvDialect(merged, &dialect);
    if (!s.ok()) {
      body_status_ = s;
      return false;
    }
    parser_->SetCsvDialect(dialect);
    return true;
  }

  bool FeedRecording(const char* data, size_t len) {
    if (!inflater_) return TakeCsvBytes(data, len);
    Status st =
        inflater_->Feed(data, len, [this](const char* d, size_t n) { return TakeCsvBytes(d, n); });
    if (!st.ok() && !GzipInflater::IsSinkStopped(st)) body_status_ = st;
    return st.ok();
  }

  // The recording's bytes as sent: the first two decide whether it is gzip'd.
  bool TakeRecordingBytes(const char* data, size_t len) {
    received_ += static_cast<int64_t>(len);
    if (received_ > options_.max_upload_bytes) {
      body_status_ =
          Status(StatusCode::kTooLarge, "the upload is larger than the limit of " +
                                            std::to_string(options_.max_upload_bytes) + " bytes");
      return false;
    }
    if (!decided_) {
      const size_t take = std::min(len, 2 - head_.size());
      head_.append(data, take);
      data += take;
      len -= take;
      if (head_.size() < 2 && !body_gzip_) return true;
      decided_ = true;
      if (body_gzip_ || LooksLikeGzip(head_.data(), head_.size())) {
        inflater_ = std::make_unique<GzipInflater>(gzip_limits_, "the recording");
      }
      if (!FeedRecording(head_.data(), head_.size())) return false;
    }
    return len == 0 || FeedRecording(data, len);
  }

  // After the last byte: a recording of one byte, and the end of a gzip stream.
  void EndRecording() {
    if (!decided_ && !head_.empty()) {
      decided_ = true;
      if (!FeedRecording(head_.data(), head_.size())) return;
    }
    if (inflater_) {
      Status st = inflater_->Finish();
      if (!st.ok()) body_status_ = st;
    }
  }

  // A multipart part begins: 'recording' or 'config', each at most once.
  bool StartPart(const httplib::MultipartFormData& header) {
    part_ = header.name;
    if (part_ == "recording") {
      if (have_recording_) {
        body_status_ =
            Status::InvalidInput("more than one 'recording' part").WithField("recording");
        return false;
      }
      have_recording_ = true;
      file_name_ = header.filename;
      if (have_config_ && !ApplyEarlyConfig()) return false;
    } else if (part_ == "config") {
      if (have_config_) {
        body_status_ = Status::InvalidInput("more than one 'config' part").WithField("config");
        return false;
      }
      have_config_ = true;
      config_after_recording_ = have_recording_;
    } else {
      body_status_ = Status::InvalidInput("unknown multipart part '" + part_.substr(0, 64) +
                                          "': expected 'recording' and 'config'")
                         .WithField(part_.substr(0, 64));
      return false;
    }
    return true;
  }

  bool TakePartBytes(const char* data, size_t len) {
    if (part_ == "recording") return TakeRecordingBytes(data, len);
    received_ += static_cast<int64_t>(len);
    if (static_cast<int64_t>(config_text_.size() + len) > options_.max_json_body_bytes) {
      body_status_ = Status(StatusCode::kTooLarge,
                            "the config part is larger than " +
                                std::to_string(options_.max_json_body_bytes) + " bytes");
      return false;
    }
    config_text_.append(data, len);
    return true;
  }

  // After a multipart body: a 'recording' part is required; the config part's keys join
  // *config (a key given in both is refused).
  void MergeParts(json* config) {
    if (!have_recording_) {
      body_status_ =
          Status::InvalidInput("no 'recording' part in the multipart body").WithField("recording");
      return;
    }
    if (!have_config_) return;
    json part_config;
    Status cs = ParseJsonText(config_text_, "config", &part_config);
    if (!cs.ok()) {
      body_status_ = cs.WithField("config");
    } else if (!part_config.is_object()) {
      body_status_ =
          Status::InvalidInput("the config part must be a JSON object").WithField("config");
    } else {
      part_config_ = part_config;
      for (auto& [key, value] : part_config.items()) {
        if (config->contains(key)) {
          body_status_ =
              Status::InvalidInput("key '" + key + "' given both in the query and the config part")
                  .WithField(key);
          break;
        }
        (*config)[key] = value;
      }
    }
  }

  const ServeOptions& options_;
  const bool body_gzip_;
  StagingFile staged_;
  Sha256 sha_;
  std::unique_ptr<RecordingParser> parser_;  // replaced when the staged file is read again
  Status parse_status_;                      // first CSV error
  Status body_status_;                       // first other error (size, I/O, multipart shape)
  std::string file_name_;
  int64_t received_ = 0;  // body bytes as sent
  GzipLimits gzip_limits_;
  std::unique_ptr<GzipInflater> inflater_;  // set when the recording is compressed
  std::string head_;                        // the first bytes, until the magic can be seen
  bool decided_ = false;                    // compressed or not is known
  int64_t csv_bytes_ = 0;
  // Multipart: the current part's name, the config part's text, which parts came.
  std::string part_;
  std::string config_text_;
  bool have_recording_ = false, have_config_ = false;
  // How the CSV is read when the config part comes after the recording (ReadAfterConfig).
  bool multipart_ = false;
  const json* query_config_ = nullptr;  // the query's config (Read's), during Read
  bool config_after_recording_ = false;
  json part_config_;        // the config part's keys
  bool deferred_ = false;   // the first reading failed at the header: staged only since
  Status deferred_status_;  // that reading's error
};

// The answer to a stored upload: 201 with the recording (and its job), Location naming the job
// when one was queued, else the recording.
void AnswerStoredUpload(const storage::RecordingInfo& info, bool existed,
                        const json& compressed_bytes, httplib::Response& res) {
  json body = {{"recording",
                {{"id", info.id},
                 {"sha256", info.sha256},
                 {"bytes", info.bytes},
                 {"rows", info.rows},
                 {"layout", info.layout},
                 {"existed", existed},
                 {"compressed_bytes", compressed_bytes},
                 {"url", "/api/v1/recordings/" + std::to_string(info.id)}}}};
  if (info.job) {
    body["job"] = {{"id", info.job->id},
                   {"status", info.job->status},
                   {"url", "/api/v1/jobs/" + std::to_string(info.job->id)},
                   {"report_url", "/jobs/" + std::to_string(info.job->id)}};
    res.set_header("Location", "/api/v1/jobs/" + std::to_string(info.job->id));
  } else {
    res.set_header("Location", "/api/v1/recordings/" + std::to_string(info.id));
  }
  res.status = 201;
  res.set_content(JsonBody(body), "application/json");
}

// A config without a method names at most the device (a string, stored in NFC).
Status CheckDeviceOnlyConfig(const json& config, CommonConfig* common) {
  if (!config.contains("device")) return Status::Ok();
  if (!config["device"].is_string()) {
    return Status::InvalidInput("'device' must be a string").WithField("device");
  }
  Status s = NormalizeSerial(config["device"].get_ref<const std::string&>(), &common->device);
  if (!s.ok()) return s;
  for (auto& [key, value] : config.items()) {
    if (key != "device" && key != "columns" && key != "delimiter" && key != "decimal") {
      return Status::InvalidInput("config key '" + key + "' given without 'method'").WithField(key);
    }
  }
  return Status::Ok();
}

}  // namespace

Status Service::Impl::CheckUploadJob(const RecordingSummary& summary, const std::string& file_name,
                                     json* config, CommonConfig* common,
                                     storage::NewRecording* rec) {
  Status s = ResolveJobReferences(store.get(), config);
  if (!s.ok()) return s;
  s = ValidateConfig(*config, common);
  if (!s.ok()) return s;
  if (!common->device.empty()) (*config)["device"] = common->device;  // the stored (NFC) serial
  if (!common->product.empty()) (*config)["product"] = common->product;
  s = CheckJobSeconds(*common, static_cast<double>(job_seconds));
  if (!s.ok()) return s;
  const Method& method = *FindMethod(common->method);
  s = CheckLogConfig(summary, *config, file_name.empty() ? "upload" : file_name);
  if (!s.ok()) return s;
  const bool log = summary.format != "csv";
  TimeUnit time_unit = TimeUnit::kSeconds;
  bool time_unit_given = false;
  s = ParseTimeUnit(*config, &time_unit, &time_unit_given);  // validated above
  if (!s.ok()) return s;
  if (method.NeedsIncreasingTime()) {  // raw-log methods
    s = CheckTimesIncrease(summary, common->method, time_unit);
    if (!s.ok()) return s;
  }
  if (!method.Reads(summary.layout)) {
    return Status::InvalidInput(std::string("method '") + common->method +
                                "' cannot read the recording's " + LayoutName(summary.layout) +
                                " layout")
        .WithField("method");
  }
  // A time column in ms or ns read as seconds would make the job compute for hours on a
  // nonsense rate: refused now, nothing stored (the summary's figures are in the file's unit,
  // whatever unit the config names; the worker checks the same for jobs on stored logs).
  if (!log && !time_unit_given && method.ReadsTime(WithoutAcceptance(*config))) {
    s = CheckTimeUnit(summary, file_name.empty() ? "upload" : file_name);
    if (!s.ok()) return s;
  }
  const RecordingShape shape{summary.rows, static_cast<int64_t>(summary.columns.size())};
  s = CheckJobBudget(*FindMethod(common->method), shape, WithoutAcceptance(*config),
                     job_memory_bytes);
  if (!s.ok()) return s;
  rec->job = storage::NewJob{common->method, common->device,
                             config->dump(-1, ' ', false, json::error_handler_t::replace)};
  return Status::Ok();
}

void Service::Impl::HandleUpload(const httplib::Request& req, httplib::Response& res,
                                 const httplib::ContentReader& reader) {
  const bool body_gzip = IsGzipEncoding(req.get_header_value(kBodyEncodingHeader));
  UploadBody body(options, body_gzip);
  auto finish = [&](int status) { metrics.ObserveUpload(body.received(), status); };

  // Config from the query string (text/csv bodies) — validated before the body is read.
  json config;
  Status s = ConfigFromQuery(req.params, &config);
  if (!s.ok()) return finish(SendStatus(res, s));
  if (const int refused = RefuseUploadMedia(req, body_gzip, res); refused != 0) {
    return finish(refused);
  }
  CsvDialect dialect;  // query keys; a config part's join them (UploadBody)
  s = ParseCsvDialect(config, &dialect);
  if (!s.ok()) return finish(SendStatus(res, s));
  body.parser().SetCsvDialect(dialect);
  s = body.Stage(staging_dir);
  if (!s.ok()) return finish(SendStatus(res, s));

  const bool read_ok = body.Read(reader, req.is_multipart_form_data(), &config);
  if (!body.body_status().ok()) {
    if (body.body_status().reason() == Reason::kDiskFull) {
      health.Note(body.body_status(), "an upload", true);
    }
    res.set_header("Connection", "close");
    return finish(SendStatus(res, body.body_status()));
  }
  if (!body.parse_status().ok()) {
    res.set_header("Connection", "close");
    return finish(SendStatus(res, body.parse_status()));
  }
  if (!read_ok) {
    // The connection broke or the body was malformed (e.g. bad chunk sizes, truncated multipart).
    res.set_header("Connection", "close");
    SendError(res, 400, "invalid_input", "the request body could not be read completely");
    return finish(400);
  }
  // A sensor log is read at Finish: the config's `streams` (query or multipart) chooses its IMUs.
  LogStreamSelection streams;
  s = ParseLogStreams(config, &streams);
  if (!s.ok()) return finish(SendStatus(res, s));
  body.parser().SetLogStreams(streams);
  s = body.parser().Finish();
  if (!s.ok()) return finish(SendStatus(res, s));

  storage::NewRecording rec = body.Recording();
  CommonConfig common;
  s = config.contains("method")
          ? CheckUploadJob(body.parser().summary(), body.file_name(), &config, &common, &rec)
          : CheckDeviceOnlyConfig(config, &common);
  if (!s.ok()) return finish(SendStatus(res, s));
  rec.device = common.device;
  s = body.staged().Close();
  if (!s.ok()) return finish(SendStatus(res, s));

  storage::RecordingInfo info;
  bool existed = false;
  s = store->PutRecording(rec, &info, &existed);
  // A stored upload is a sound write (the disk is not full) and repairs a damaged copy of the
  // same bytes (Store::PutRecording).
  health.Note(s, s.ok() ? "recording " + std::to_string(info.id) : "an upload", true);
  if (!s.ok()) return finish(SendStatus(res, s));
  AnswerStoredUpload(info, existed, body.compressed_bytes(), res);
  // An inertial log is parsed once more in the background into the parsed-columns cache, with
  // the upload's reading rules, so that its first check, /segments or job does not parse it.
  if (info.layout == LayoutName(Layout::kArray))
    column_cache->Prefetch(store.get(), info.id, config);
  if (info.job) workers->Notify();
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
  if (!common.product.empty()) config["product"] = common.product;
  s = CheckJobSeconds(common, static_cast<double>(job_seconds));
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::RecordingInfo recording;
  s = store->GetRecording(recording_id, &recording);
  if (!s.ok()) return (void)SendStatus(res, s);
  InheritCsvDialect(recording, &config);
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
