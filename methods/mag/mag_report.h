// The mag method's part of the HTML pages (methods/mag/mag_report.cc): per magnetometer the
// parameters with 1σ, the raw and calibrated samples on the sphere (three projections), |m| − F
// over time with the disturbed spans marked, and the coverage map of the field's directions; the
// partial report of a failed run shows what was found (coverage map, residuals). Key figures:
// field estimate and |m| residual; device-page drift of the hard iron between calibrations.
#ifndef CALIBD_METHODS_MAG_MAG_REPORT_H_
#define CALIBD_METHODS_MAG_MAG_REPORT_H_

#include "web/method_report.h"

namespace calibd::web::internal {

// Its registry entry (methods/registry.cc).
const MethodReport& MagMethodReport();

}  // namespace calibd::web::internal

#endif  // CALIBD_METHODS_MAG_MAG_REPORT_H_
