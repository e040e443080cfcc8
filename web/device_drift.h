// Drift of the raw-log methods on the device page (`/devices/{serial}`, SPEC §5 "drift between
// calibrations"): how a device's noise terms (`noise` jobs) and IMU intrinsics (`imu` jobs) move
// from one accepted calibration to the next; the noise and imu reports (MethodReport::Drift)
// return them. The pca and array drift live in their own reports.
//
// Input: one method's accepted, not revoked jobs of one device, oldest first, with their SPEC §7
// result JSON, each read once as its typed result (results/noise_result.h, results/imu_result.h;
// undefined values render as "–" or "not visible"). A result that does not read adds no rows and
// is listed under the table (ul.drift-unreadable: its job and the reader's message naming the
// path); nothing throws. Output: an HTML fragment; every user-controlled string (channel and IMU
// names) is escaped. Pure and thread-safe.
//
// What is shown:
//   noise  one table per sensor type (accelerometers: channels a*, gyroscopes: g*), a row per
//          calibration and channel: white noise N (unit/√Hz), bias instability B (unit, with the
//          τ of its floor) and random walk K (unit/s/√Hz), each ± 1σ or "not visible", and
//          beside each its change against the previous calibration that has the channel:
//          relative (%) and in standard deviations of the difference, √(σ_prev² + σ_now²).
//          A plot per sensor type of N over time with ±1σ bars.
//   imu    one table, a row per calibration, IMU and sensor (accelerometer, gyroscope): scale
//          factors K (x y z ± 1σ, SI per reading unit), misalignment T − I (mrad: its largest
//          |entry|, the 3 rows collapsed beneath it in a <details>), biases
//          b (x y z ± 1σ, reading units), and the changes against the previous calibration of that
//          IMU: Δscale in ppm, the largest |ΔT| entry in mrad, Δb in reading units, each with its
//          size in standard deviations. A plot of every scale factor's change (ppm) since the
//          first calibration. T is comparable between calibrations: the body frame is the
//          accelerometer's by convention (SPEC §7), not a choice of the fit.
//   A change of 3 or more standard deviations is marked (class drift-significant): more than
//   the two calibrations' own uncertainty explains. Each calibration's cell holds its link and,
//   below, its date; the tables use a smaller type and wrapping headings so that they fit a
//   1280 px wide window (tests/web/browser_pages.sh measures it).
//
// DOM hooks (stable): table.table-drift-noise (one per sensor type, data-sensor="accelerometer"
// | "gyroscope"), table.table-drift-imu, td.drift-significant, svg.plot-drift-noise-accel,
// svg.plot-drift-noise-gyro, svg.plot-drift-imu-scale. At most kMaxDriftCalibrations (the newest)
// are listed in the tables, with a note; the plots show every calibration.
#ifndef CALIBD_WEB_DEVICE_DRIFT_H_
#define CALIBD_WEB_DEVICE_DRIFT_H_

#include <cstddef>
#include <string>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

constexpr size_t kMaxDriftCalibrations = 40;

// The noise terms of `jobs` (noise results) over time. "" when jobs is empty.
std::string NoiseDriftHtml(const std::vector<const JobSummary*>& jobs);

// The IMU intrinsics of `jobs` (imu results) over time. "" when jobs is empty.
std::string ImuDriftHtml(const std::vector<const JobSummary*>& jobs);

}  // namespace calibd::web

#endif  // CALIBD_WEB_DEVICE_DRIFT_H_
