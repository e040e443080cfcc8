// Drift of the noise method on the device page (`/devices/{serial}`, SPEC §5 "drift between
// calibrations"): how a device's noise terms move from one accepted calibration to the next.
// Each result is read once as its typed result (methods/noise/noise_result.h; undefined values
// render as "–" or "not visible"). A result that does not read adds no rows and is listed under
// the table (ul.drift-unreadable: its job and the reader's message naming the path); nothing
// throws. One table per sensor type (accelerometers: channels a*, gyroscopes: g*), a row per
// calibration and channel: white noise N (unit/√Hz), bias instability B (unit, with the τ of its
// floor) and random walk K (unit/s/√Hz), each ± 1σ or "not visible", and beside each its change
// against the previous calibration that has the channel: relative (%) and in standard deviations
// of the difference (web/drift_table.h). A plot per sensor type of N over time with ±1σ bars.
//
// DOM hooks (stable): table.table-drift-noise (one per sensor type, data-sensor="accelerometer"
// | "gyroscope"), td.drift-significant, svg.plot-drift-noise-accel, svg.plot-drift-noise-gyro.
#ifndef CALIBD_METHODS_NOISE_NOISE_DRIFT_H_
#define CALIBD_METHODS_NOISE_NOISE_DRIFT_H_

#include <string>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

// The noise terms of `jobs` (accepted noise results of one device, oldest first) over time, as
// HTML. "" when jobs is empty.
std::string NoiseDriftHtml(const std::vector<const JobSummary*>& jobs);

}  // namespace calibd::web

#endif  // CALIBD_METHODS_NOISE_NOISE_DRIFT_H_
