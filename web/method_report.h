// MethodReport: what the HTML pages show of one method's results — its section of the job report,
// its key figures in the history and device tables, its drift between calibrations on the device
// page, and the export links — and the registry of them (web/method_reports.cc), one line per
// method. The server's registry (server/methods.cc) has the same methods; a server test checks
// that every server method has a report here with the same export formats.
//
// Adding a method's report: web/<name>_report.cc with a class implementing MethodReport (its
// accessor declared in web/reports.h) and one line in AllMethodReports(). pages.cc, history and
// device pages find it here.
#ifndef CALIBD_WEB_METHOD_REPORT_H_
#define CALIBD_WEB_METHOD_REPORT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

class MethodReport {
 public:
  virtual ~MethodReport() = default;
  // The result's `method` value ("pca", ...).
  virtual const char* method() const = 0;
  // The method's part of the job page after the model statement (parameters with uncertainties,
  // plots); the page adds the header, downloads and the diagnostics table. Never throws for a
  // result of an unexpected shape: says "not available" for what it cannot read.
  virtual std::string Section(const JobView& view) const = 0;
  // The method's part of a failed job's page: what its partial diagnostics
  // (view.job.error_detail: {"method", "usable": false, "diagnostics", "warnings"}) show, e.g.
  // the statics found on a timeline; the page adds the reason, message, advice and the
  // diagnostics table. "" when the method has nothing to draw. Never throws for a detail of an
  // unexpected shape.
  virtual std::string Partial(const JobView& view) const {
    (void)view;
    return "";
  }
  // Key figures for the history and device tables, plain text (escaped by the caller); "" when
  // not available (the tables show a dash).
  virtual std::string KeyFigures(const nlohmann::json& result) const {
    (void)result;
    return "";
  }
  // The drift between successive accepted results (>= 2, oldest first) on the device page; ""
  // when the method has no drift tables.
  virtual std::string Drift(const std::vector<const JobSummary*>& jobs) const {
    (void)jobs;
    return "";
  }
  // A download besides the JSON (GET /api/v1/devices/{serial}/calibration?format=FORMAT).
  struct Download {
    std::string format;  // "csv", "h", "yaml"
    std::string label;   // link text: "CSV"
  };
  // In the order the pages offer them; the same formats as the server's Method::ExportFormats().
  virtual std::vector<Download> Downloads() const = 0;
};

// Every method's report, in the order of the server's registry. Never empty; the pointers live
// for the process.
const std::vector<const MethodReport*>& AllMethodReports();
// The report of `method`, or null.
const MethodReport* FindMethodReport(std::string_view method);

}  // namespace calibd::web

#endif  // CALIBD_WEB_METHOD_REPORT_H_
