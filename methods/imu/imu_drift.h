// Drift of the imu method on the device page (`/devices/{serial}`, SPEC §5 "drift between
// calibrations"): how a device's IMU intrinsics move from one accepted calibration to the next.
// Each result is read once as its typed result (methods/imu/imu_result.h). A result that does not
// read adds no rows and is listed under the table (ul.drift-unreadable); nothing throws. One
// table, a row per calibration, IMU and sensor (accelerometer, gyroscope): scale factors K (x y z
// ± 1σ, SI per reading unit), misalignment T − I (mrad: its largest |entry|, the 3 rows collapsed
// beneath it in a <details>), biases b (x y z ± 1σ, reading units), and the changes against the
// previous calibration of that IMU: Δscale in ppm, the largest |ΔT| entry in mrad, Δb in reading
// units, each with its size in standard deviations (web/drift_table.h). A plot of every scale
// factor's change (ppm) since the first calibration. T is comparable between calibrations: the
// body frame is the accelerometer's by convention (SPEC §7), not a choice of the fit.
//
// DOM hooks (stable): table.table-drift-imu, td.drift-significant, svg.plot-drift-imu-scale.
#ifndef CALIBD_METHODS_IMU_IMU_DRIFT_H_
#define CALIBD_METHODS_IMU_IMU_DRIFT_H_

#include <string>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

// The IMU intrinsics of `jobs` (accepted imu results of one device, oldest first) over time, as
// HTML. "" when jobs is empty.
std::string ImuDriftHtml(const std::vector<const JobSummary*>& jobs);

}  // namespace calibd::web

#endif  // CALIBD_METHODS_IMU_IMU_DRIFT_H_
