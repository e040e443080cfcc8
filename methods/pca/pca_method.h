// JSON glue of the `pca` method: config keys (SPEC §3) to core::PcaOptions, a parsed recording to
// the result JSON (SPEC §4), and the simulated recording of `calibd simulate pca`.
#ifndef CALIBD_SERVER_PCA_METHOD_H_
#define CALIBD_SERVER_PCA_METHOD_H_

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "core/pca.h"
#include "core/pca_simulation.h"
#include "formats/recording.h"
#include "methods/method.h"
#include "methods/pca/pca_result.h"

namespace calibd::server {

// The `pca` method for the registry (methods/method.h): reads the pca_averaged and pca_raw layouts.
const Method& PcaMethod();

// Reads the pca keys of a config object (SPEC §3): dimension, magnitude, nominal (m×d array of
// arrays, one row per sensor), refine, bias ("none" | "estimate"), noise_std; the common keys
// method and device are ignored. Unknown keys and wrong types are kInvalidInput with
// WithField(key) and a message naming the key. The number of sensors is not known here: nominal's
// column count is checked against d, its row count in RunPca.
Status ParsePcaConfig(const nlohmann::json& config, core::PcaOptions* options);

// Runs the calibration on a parsed recording and writes the SPEC §4 result, the typed
// results::PcaResult (methods/pca/pca_result.h) as JSON through results::ToJson:
//   {"method":"pca","schema_version":1,"parameters":{...},"uncertainty":{...},
//    "diagnostics":{...},"warnings":[...]}
// For the raw layout the reported bias of each sensor is the mean over positions of its static
// means, with the standard error of that mean as bias_std. Values that are undefined (e.g. an
// uncertainty without a noise estimate, the rank gap when there is no σ_{d+1}) are written as
// null, never NaN. Deterministic. Errors as core::CalibratePca (the message of a
// kNotDeterminable says what to record instead, Status::reason() why); on an error from the
// numerics `result` holds the partial diagnostics {"method": "pca", "usable": false,
// "diagnostics", "warnings"} (no parameters).
Status RunPca(const PcaRecording& recording, const core::PcaOptions& options,
              nlohmann::json* result);
// The same, typed (on an error: envelope.usable false, no parameters or uncertainty).
Status RunPca(const PcaRecording& recording, const core::PcaOptions& options,
              results::PcaResult* result);

// The typed result of an already computed core result (used by RunPca; without the recording's
// diagnostics position_labels and removed_bias).
results::PcaResult MakePcaResult(const core::PcaResult& result);

// The acceptance gate of a pca result (Method::Judge): orientation coverage (min_scatter,
// min_design; the reason carries diagnostics.coverage.advice, naming the missing orientations;
// skipped for a result stored before coverage existed, which the other rules still judge),
// scale factors against the nominal (|nominal_i| when `nominal` is given, else 1 when the
// magnitude is known: readings in the field's unit; not judged for an unknown magnitude) with
// scale_range and implausible_factor (a unit mix-up between readings and magnitude is named),
// 1 sigma of scale, axis and bias, and the residual against a given noise_std (max_chi2).
// A result that does not read (results::FromJson) is rejected naming the reader's message; so is
// a failed run's partial document (nothing to judge).
void JudgePca(const nlohmann::json& result, const nlohmann::json& config,
              const AcceptanceLimits& limits, Verdict* verdict);
// The same on the typed result and the parsed config (nominal is options.nominal).
void JudgePca(const results::PcaResult& result, const core::PcaOptions& options,
              const AcceptanceLimits& limits, Verdict* verdict);

// For `calibd simulate pca`: the averaged-layout CSV (`position,g0_x,...,g3_z`, %.17g), the
// config ({"method":"pca","magnitude":c,"nominal": a_model as m×d}, plus "bias":"estimate" when
// the simulation has biases) and the truth ({"sensors":[{"name","sensitivity","bias"}],"v": n×d,
// "seed", "options"}). Deterministic for a seed.
Status SimulatePcaFiles(const core::PcaSimulationOptions& options, std::string* csv,
                        nlohmann::json* config, nlohmann::json* truth);

// Method::Plan of pca (methods/pca/pca_plan.cc): needs the config's nominal and noise_std.
Status PlanPca(const nlohmann::json& config, const PlanProtocol& protocol,
               const AcceptanceLimits& limits, nlohmann::json* out);

// Exports of a pca result (methods/pca/pca_exports.cc; formats in methods/exports.h).
Status PcaResultToCsv(const nlohmann::json& result, std::string* out);
Status PcaResultToHeader(const nlohmann::json& result, const ExportContext& context,
                         std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_PCA_METHOD_H_
