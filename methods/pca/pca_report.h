// The pca method's part of the HTML pages (methods/pca/pca_report.cc): its section of the job
// page, key figures for the history and device tables, drift on the device page.
#ifndef CALIBD_METHODS_PCA_PCA_REPORT_H_
#define CALIBD_METHODS_PCA_PCA_REPORT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/method_report.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web::internal {

struct PcaFigures {
  double worst_rel_scale_std = kNaN;  // max σ(scale)/scale
  double worst_scale_std = kNaN;
  double rank_gap = kNaN;
};
PcaFigures ComputePcaFigures(const json& result);
std::string PcaReport(const JobView& view);
std::string PcaDrift(const std::vector<const JobSummary*>& jobs);
// The partial report of a failed job (MethodReport::Partial).
std::string PcaPartial(const JobView& view);

// Its registry entry (methods/registry.cc).
const MethodReport& PcaMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_METHODS_PCA_PCA_REPORT_H_
