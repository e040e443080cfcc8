// What the files of the `array` method share (internal to methods/array/, not for other
// methods): the config key readers both models use, the saturation pass both runs make, and the
// two models' runs behind RunArray's dispatch on "model".
//   array_method.cc       the Method (keys, Judge, exports, simulate options), RunArray, and the
//                         definitions below but the two runs
//   array_positions.cc    model "positions" (the default): config, accelerometer_calibration,
//                         run and result, simulated files
//   array_full_method.cc  model "full" (SPEC §7): config, run and result, simulated files
//   array_plan.cc         the plan of the positions model; array_full_plan.cc: the full model's
// Stateless functions: safe to call from any thread.
#ifndef CALIBD_METHODS_ARRAY_ARRAY_INTERNAL_H_
#define CALIBD_METHODS_ARRAY_ARRAY_INTERNAL_H_

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array.h"
#include "core/array_full.h"
#include "core/stop_token.h"
#include "formats/recording.h"
#include "results/saturation.h"

namespace calibd::server::array_detail {

// kInvalidInput "config key 'KEY': MESSAGE" WithField(key).
Status KeyError(const std::string& key, const std::string& message);

// A finite JSON number.
Status ReadNumber(const nlohmann::json& v, const std::string& key, double* out);
// A finite JSON number > 0.
Status ReadPositive(const nlohmann::json& v, const std::string& key, double* out);
// An integral JSON number (1000 or 1000.0) within [lo, hi].
Status ReadInteger(const nlohmann::json& v, const std::string& key, int64_t lo, int64_t hi,
                   int64_t* out);
Status ReadString(const nlohmann::json& v, const std::string& key, std::string* out);

// The config's `geometry` {"positions": [[x,y,z], ...], "reference": k} (required): fills
// problem->nominal_positions (metres, 3×K) and ->reference (default 0) only.
Status ParseGeometry(const nlohmann::json& config, core::ArrayProblem* problem);

// The config's `tolerance`, when given: a number >= 0 and < 1 (0: never stop early) into
// *tolerance, else *tolerance untouched.
Status ReadTolerance(const nlohmann::json& config, double* tolerance);

// `gyro_unit` of an array config: "rad/s" (default) or "deg/s" (*gyro_in_degrees set; left
// untouched without the key).
Status ParseGyroUnit(const nlohmann::json& config, bool* gyro_in_degrees);

// The config asks for model "full" (a string "full" under "model").
bool IsFullModel(const nlohmann::json& config);

// `v` printed with %.17g (the simulated CSV files).
std::string FormatG17(double v);

// Saturation of an array log (core/saturation.h), on the readings in SI (m/s², rad/s) before
// any correction: a configured accel_saturation / gyro_saturation (symmetric) overrides the search
// for its kind; otherwise the clip levels found in the data give one symmetric limit per kind
// (the tightest over the kind's channels, core::SymmetricLimit), which the fit drops like a
// configured one (every sample with any |component| at or beyond it; model full: never part of a
// static). Sets the limits in *accel_limit / *gyro_limit and, when anything is pinned, the
// diagnostics and a warning. `degrees`: the diagnostics give the gyroscope levels in deg/s.
Status ArraySaturation(const Eigen::MatrixXd& accel, const std::vector<std::string>& accel_names,
                       const Eigen::MatrixXd& gyro, const std::vector<std::string>& gyro_names,
                       bool degrees, const core::StopToken* stop,
                       std::optional<double>* accel_limit, std::optional<double>* gyro_limit,
                       std::optional<results::SaturationDiagnostics>* diagnostics,
                       std::vector<std::string>* warnings);

// The two models' runs, with RunArray's contract (methods/array/array_method.h) for a config of
// their model: RunArray calls the one the config's "model" names.
Status RunArrayPositions(ArrayRecording recording, const nlohmann::json& config,
                         nlohmann::json* result, const core::StopToken* stop,
                         core::TaskExecutor executor);
Status RunArrayFull(ArrayRecording recording, const nlohmann::json& config, nlohmann::json* result,
                    const core::StopToken* stop, core::TaskExecutor executor);

// The result JSON of a full-model fit whose status is `status` (not OK: the partial diagnostics
// of a failed run, usable false), gyroscope figures in the configured unit (`degrees`: deg/s);
// `saturation` and its warnings as ArraySaturation gave them (none: nullopt, empty). What
// RunArrayFull stores, and what the plan judges (methods/array/array_full_plan.cc).
nlohmann::json FullResultJson(const core::ArrayFullResult& r, const Status& status,
                              const core::ArrayFullProblem& problem,
                              const core::ArrayFullOptions& options, bool degrees,
                              std::optional<results::SaturationDiagnostics> saturation,
                              std::vector<std::string> saturation_warnings);

}  // namespace calibd::server::array_detail

#endif  // CALIBD_METHODS_ARRAY_ARRAY_INTERNAL_H_
