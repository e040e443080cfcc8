#include "methods/exports.h"

#include <string>

#include "methods/method.h"
#include "methods/registry.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// Asks the result's method to write `format`; kInvalidInput naming `format` when the method has
// no such export (`what` is the format's name for the message).
Status ExportAs(const std::string& format, const char* what, const json& result,
                const ExportContext& context, std::string* out) {
  const auto it = result.is_object() ? result.find("method") : result.end();
  const Method* method =
      it != result.end() && it->is_string() ? FindMethod(it->get<std::string>()) : nullptr;
  if (method == nullptr) return Status::Internal("stored result has an unknown method");
  for (const ExportFormat& f : method->ExportFormats()) {
    if (f.format == format) return method->Export(format, result, context, out);
  }
  std::string with;
  for (const Method* m : AllMethods()) {
    for (const ExportFormat& f : m->ExportFormats()) {
      if (f.format == format) {
        with += std::string(with.empty() ? "" : ", ") + m->name() + " results (" + f.label + ")";
      }
    }
  }
  return Status::InvalidInput("format=" + format + " (" + what + ") is available for " +
                              (with.empty() ? std::string("no method") : with) + ", not for " +
                              method->name() + " results")
      .WithField("format");
}

}  // namespace

ExportFormat CsvFormat() { return {"csv", "CSV", "text/csv", ""}; }
ExportFormat CHeaderFormat() { return {"h", "C header", "text/x-c", ""}; }

Status NoSuchExport(const std::string& format, const char* method) {
  return Status::InvalidInput(std::string(method) + " results have no format=" + format)
      .WithField("format");
}

Status ResultToCsv(const json& result, std::string* out) {
  return ExportAs("csv", "CSV", result, ExportContext{}, out);
}

Status ResultToKalibrYaml(const json& result, const ExportContext& context, std::string* out) {
  return ExportAs("yaml", "YAML", result, context, out);
}

Status ResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return ExportAs("h", "C header", result, context, out);
}

void MarkNotAccepted(const std::string& format, const ExportContext& context, std::string* text) {
  if (IsAcceptedExport(context) || (format != "csv" && format != "yaml")) return;
  const std::string line =
      "# NOT FOR USE: job " + std::to_string(context.job_id) + "'s result was " + context.state +
      (context.state == "rejected" ? " by the acceptance gate" : " by a person") +
      "; it is never served as device calibration\n";
  size_t at = 0;
  if (text->rfind("%YAML", 0) == 0) {
    const size_t end = text->find('\n');
    at = end == std::string::npos ? text->size() : end + 1;
  }
  text->insert(at, line);
}

}  // namespace calibd::server
