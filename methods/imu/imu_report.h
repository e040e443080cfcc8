// The imu method's part of the HTML pages (methods/imu/imu_report.cc): its section of the job
// page, key figures for the history and device tables, drift on the device page.
#ifndef CALIBD_METHODS_IMU_IMU_REPORT_H_
#define CALIBD_METHODS_IMU_IMU_REPORT_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/method_report.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web::internal {

std::string ImuReport(const JobView& view);
// The partial report of a failed job (MethodReport::Partial).
std::string ImuPartial(const JobView& view);

// Its registry entry (methods/registry.cc).
const MethodReport& ImuMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_METHODS_IMU_IMU_REPORT_H_
