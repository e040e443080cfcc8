// MethodReport: what the HTML pages show of one method's results: its section of the job report,
// its partial report of a failed job, its key figures in the history and device tables and its
// drift between calibrations on the device page. Each method implements it in its folder
// (methods/<name>/<name>_report.cc) and names it in its registry entry (methods/registry.h);
// the pages (web/pages/) find it there. The export links come from the method itself
// (Method::ExportFormats).
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
  // The result's `method` value: its method's registered name.
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
};

}  // namespace calibd::web

#endif  // CALIBD_WEB_METHOD_REPORT_H_
