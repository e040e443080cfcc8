// Drift of the thermal method on the device page (`/devices/{serial}`, SPEC §5 "drift between
// calibrations"): how a device's bias-against-temperature curves move from one accepted
// calibration to the next. Each result is read from its JSON (parameters.imus[].{t_ref, t_min,
// t_max, accelerometer|gyroscope.bias.coefficients} and uncertainty.imus[].…bias.covariance); one
// that does not read adds no rows and is listed under the table (ul.drift-unreadable).
//
// The curves are relative to bias(t_ref) and t_ref differs between calibrations (by default the
// middle of each log's range), so two curves are compared by their shape over the temperatures
// both logs covered: D(T) = d(T) − d(T0), T0 the middle of the common range, on 21 points of it.
// A cell gives, per axis, the largest |D_now − D_before| (SI: m/s², rad/s) and where it occurs,
// with its size in σ of the difference √(gᵀC_before g + gᵀC_now g), g_k = (T − t_ref)^k −
// (T0 − t_ref)^k (exact: the coefficients' covariance is stored); the largest z over the grid
// marks the cell (web/drift_table.h). The gyroscope's absolute bias at t_ref is compared only
// when both calibrations used the same t_ref (within 0.05 °C): otherwise its σ would need the
// intercept's covariance with the curve, which the result does not keep. Logs whose ranges
// overlap by less than 1 °C are not compared (said in the cell).
// A plot per IMU and sensor draws every calibration's D(T) of the axis that moved most, over the
// range all of them covered (each its own range, relative to its own t_ref, when they share none).
//
// DOM hooks (stable): table.table-drift-thermal, td.drift-significant, svg.plot-drift-thermal-*.
#ifndef CALIBD_METHODS_THERMAL_THERMAL_DRIFT_H_
#define CALIBD_METHODS_THERMAL_THERMAL_DRIFT_H_

#include <string>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

// The thermal curves of `jobs` (accepted thermal results of one device, oldest first) over time,
// as HTML. "" when jobs is empty.
std::string ThermalDriftHtml(const std::vector<const JobSummary*>& jobs);

}  // namespace calibd::web

#endif  // CALIBD_METHODS_THERMAL_THERMAL_DRIFT_H_
