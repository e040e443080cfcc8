// The array method's part of the HTML pages (methods/array/array_report.cc): its section of the job
// page, key figures for the history and device tables, drift on the device page.
#ifndef CALIBD_METHODS_ARRAY_ARRAY_REPORT_H_
#define CALIBD_METHODS_ARRAY_ARRAY_REPORT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/method_report.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web::internal {

struct ArrayFigures {
  double rms_offset = kNaN;   // metres, over the non-reference triads
  double worst_sigma = kNaN;  // metres, max over all coordinates
};
ArrayFigures ComputeArrayFigures(const json& result);
std::string ArrayReport(const JobView& view);
std::string ArrayDrift(const std::vector<const JobSummary*>& jobs);

// Its registry entry (methods/registry.cc).
const MethodReport& ArrayMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_METHODS_ARRAY_ARRAY_REPORT_H_
