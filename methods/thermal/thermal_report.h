// The thermal method's part of the HTML pages (methods/thermal/thermal_report.cc): per IMU and
// channel the bias curve with its 1σ band and the window means, the order table and the
// heating/cooling comparison; the device page's drift of the curves
// (methods/thermal/thermal_drift.h).
#ifndef CALIBD_METHODS_THERMAL_THERMAL_REPORT_H_
#define CALIBD_METHODS_THERMAL_THERMAL_REPORT_H_

#include "web/method_report.h"

namespace calibd::web::internal {

// Its registry entry (methods/registry.cc).
const MethodReport& ThermalMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_METHODS_THERMAL_THERMAL_REPORT_H_
