// The per-method report sections of the job page, their key figures and the device page's drift
// tables (web/<method>_report.cc). Internal to web/.
#ifndef CALIBD_WEB_REPORTS_H_
#define CALIBD_WEB_REPORTS_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/method_report.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web::internal {

// pca (web/pca_report.cc).
struct PcaFigures {
  double worst_rel_scale_std = kNaN;  // max σ(scale)/scale
  double worst_scale_std = kNaN;
  double rank_gap = kNaN;
};
PcaFigures ComputePcaFigures(const json& result);
std::string PcaReport(const JobView& view);
std::string PcaDrift(const std::vector<const JobSummary*>& jobs);

// array (web/array_report.cc).
struct ArrayFigures {
  double rms_offset = kNaN;   // metres, over the non-reference triads
  double worst_sigma = kNaN;  // metres, max over all coordinates
};
ArrayFigures ComputeArrayFigures(const json& result);
std::string ArrayReport(const JobView& view);
std::string ArrayDrift(const std::vector<const JobSummary*>& jobs);

// noise (web/noise_report.cc) and imu (web/imu_report.cc).
std::string NoiseReport(const JobView& view);
std::string ImuReport(const JobView& view);

// The partial reports of failed jobs (MethodReport::Partial) of pca and imu (noise's and array's
// are private to their files).
std::string PcaPartial(const JobView& view);
std::string ImuPartial(const JobView& view);

// The registry entries (web/method_reports.cc).
const MethodReport& PcaMethodReport();
const MethodReport& ArrayMethodReport();
const MethodReport& ImuMethodReport();
const MethodReport& NoiseMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_WEB_REPORTS_H_
