// The acceptance gate (SPEC §4 `verdict`, issue #11): every result is judged against limits before
// a production line may fetch it. Each method names its limits with their built-in defaults
// (Method::AcceptanceKeys, in server/<name>_method.cc beside its Judge); this file holds only the
// generic machinery: the keys several methods share, the validation of a method's `acceptance`
// object, the merge of built-in defaults, server-wide defaults (`calibd serve --acceptance
// FILE.json`) and the config's `acceptance` object, the Verdict, and the helpers the methods'
// judges share (Method::Judge).
//
// A limit's value is a number, or null for "no limit". A verdict is "accepted" when no rule
// fired, else "rejected" with one reason per failed rule, in words for a line operator.
#ifndef CALIBD_SERVER_ACCEPTANCE_H_
#define CALIBD_SERVER_ACCEPTANCE_H_

#include <initializer_list>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "results/triad.h"

namespace calibd::server {

// One key of the `acceptance` object of a method.
struct AcceptanceKey {
  const char* name;
  const char* meaning;                  // with its unit, for error messages and the README
  std::optional<double> default_value;  // nullopt: no limit unless set
  double max_value = 1e300;             // a value above this is refused (a rate: 0.5)
};

// Keys several methods share, with one meaning and default wherever they appear (a method lists
// them in its Method::AcceptanceKeys). Defaults are meant to pass a sound calibration of a MEMS
// sensor made as the README describes and to stop the mistakes seen on production lines: poorly
// spread orientations, unit mix-ups, too few or too noisy data. A line tightens them to its own
// tolerances (`serve --acceptance`).
namespace limit_keys {
// pca, imu and array (the latter only for `model: full` results, parameters.imus).
inline constexpr AcceptanceKey kMaxScaleStd = {
    "max_scale_std", "largest 1 sigma of a scale factor, relative to it (0.01 = 1 %)", 0.01};
inline constexpr AcceptanceKey kMaxAxisStd = {
    "max_axis_std",
    "largest 1 sigma of an axis direction (pca) or misalignment entry (imu, array full), rad",
    0.01};  // 0.57 degrees
inline constexpr AcceptanceKey kScaleRange = {
    "scale_range",
    "allowed relative deviation of a scale factor from its nominal, |scale/nominal - 1|", 0.1};
inline constexpr AcceptanceKey kImplausible = {
    "implausible_factor",
    "a scale factor this many times above or below its nominal is physically implausible (a "
    "unit mix-up) and rejected even when scale_range is null",
    3.0};
inline constexpr AcceptanceKey kMaxChi2 = {
    "max_chi2",
    "largest residual against the noise: mean squared residual / sigma^2 (1 when the model "
    "explains the data down to the noise)",
    4.0};
// imu and array full (JudgeImuTriads): biases in SI, (bias - nominal bias) x nominal unit.
inline constexpr AcceptanceKey kAccelBiasStd = {
    "max_accel_bias_std", "largest 1 sigma of an accelerometer bias, m/s^2", 0.05};
inline constexpr AcceptanceKey kGyroBiasStd = {"max_gyro_bias_std",
                                               "largest 1 sigma of a gyroscope bias, rad/s", 0.005};
inline constexpr AcceptanceKey kAccelBias = {
    "max_accel_bias", "largest accelerometer bias (beyond the nominal bias), m/s^2", 2.0};
inline constexpr AcceptanceKey kGyroBias = {
    "max_gyro_bias", "largest gyroscope bias (beyond the nominal bias), rad/s", 0.2};  // 11 deg/s
// Every method (added by AcceptanceKeys(method)); judged by the worker against the store
// (server/fleet.h ApplyFleetGate). No limit by default: a line opts in once its fleet is known.
inline constexpr AcceptanceKey kMaxFleetZ = {
    "max_fleet_z",
    "largest robust |z| of a parameter against the accepted calibrations of the other devices "
    "of the upload's product (applies when the config names a product and a parameter is known "
    "for at least 8 of its devices)",
    std::nullopt};
// Every method, with max_fleet_z: the same comparison with the threshold set per parameter from
// the fleet's size and the number of parameters compared, so that a unit drawn from the fleet's
// own distribution is rejected with this probability (core/fleet_stats.h RobustZCritical at
// Šidák's level). Where both are set, the smaller threshold applies.
inline constexpr AcceptanceKey kMaxFleetFalseAlarm = {
    "max_fleet_false_alarm",
    "probability, in [0, 0.5], that a unit like the fleet's others is rejected by the fleet "
    "comparison: each parameter's robust |z| threshold is calibrated to it for the fleet's size "
    "and the number of parameters compared (a product and 8 devices as for max_fleet_z)",
    std::nullopt, 0.5};
}  // namespace limit_keys

// The keys JudgeImuTriads reads, in this order: kMaxScaleStd, kMaxAxisStd, kScaleRange,
// kImplausible, kAccelBiasStd, kGyroBiasStd, kAccelBias, kGyroBias (imu, array full).
const std::vector<AcceptanceKey>& ImuTriadKeys();

// The parts one after the other: a method's table built from shared runs of keys.
std::vector<AcceptanceKey> JoinKeys(std::initializer_list<std::vector<AcceptanceKey>> parts);

// The keys of the registered method `method`: its Method::AcceptanceKeys, then the keys every
// method has (limit_keys::kMaxFleetZ, kMaxFleetFalseAlarm); empty for a name the registry
// (methods/registry.cc) does not know. Thread-safe; the reference stays valid.
const std::vector<AcceptanceKey>& AcceptanceKeys(const std::string& method);

// The limits in force for one result: every key of the method, nullopt = no limit.
struct AcceptanceLimits {
  std::map<std::string, std::optional<double>> values;
  std::optional<double> Get(const std::string& key) const;
  nlohmann::json ToJson() const;  // {key: number | null}
};

// Checks one method's acceptance object: a JSON object whose keys are the method's keys and whose
// values are numbers >= 0 (or null: no limit). kInvalidInput naming the key as
// `field_prefix` + "." + key (e.g. "acceptance.max_scale_std"); `where` starts the message
// (e.g. "config key 'acceptance'").
Status ValidateAcceptance(const nlohmann::json& value, const std::string& method,
                          const std::string& where, const std::string& field_prefix);

// Checks a server-wide defaults file's content: an object {"<method>": {...}, ...}
// (every method optional), each as ValidateAcceptance. `file` names the file in messages.
Status ValidateServerAcceptance(const nlohmann::json& value, const std::string& file);

// Reads and checks a server-wide defaults file (`--acceptance FILE.json`). kInvalidInput naming
// the file (and line/column of a JSON syntax error, or the offending key).
Status LoadAcceptanceFile(const std::string& path, nlohmann::json* out);

// The limits for a result of `method`: built-in defaults, overridden key by key by
// server_defaults[method] (server_defaults may be null or lack the method), overridden key by
// key by config["acceptance"] (may be absent). Both must have been validated.
AcceptanceLimits EffectiveAcceptance(const std::string& method,
                                     const nlohmann::json& server_defaults,
                                     const nlohmann::json& config);

// The gate's answer for one result.
class Verdict {
 public:
  void Reject(std::string reason) { reasons_.push_back(std::move(reason)); }
  bool accepted() const { return reasons_.empty(); }
  const std::vector<std::string>& reasons() const { return reasons_; }
  // {"status": "accepted" | "rejected", "reasons": [...], "limits": limits.ToJson()}
  nlohmann::json ToJson(const AcceptanceLimits& limits) const;

 private:
  std::vector<std::string> reasons_;
};

// ---- Helpers shared by the judges ----

// A number for people: 3 significant digits ("0.0123", "9.81", "1.2e-05").
std::string Fmt(double x);
// A finite number at `j`, or nullopt (null, missing, not a number).
std::optional<double> Number(const nlohmann::json& j);

// Items that fail one rule, gathered so the verdict has one reason per rule: "<rule>: a (1.2),
// b (3.4)" listing at most 6 items and "and N more".
class Offenders {
 public:
  void Add(const std::string& item) { items_.push_back(item); }
  bool empty() const { return items_.empty(); }
  // Rejects with `rule` + ": " + the items, when there are any.
  void RejectInto(Verdict* verdict, const std::string& rule) const;

 private:
  std::vector<std::string> items_;
};

// The rule every gate applies to the values it would serve: a parameter that is not a finite number
// (null in the JSON) never reaches a device, whatever the limits (set or not).
inline constexpr char kNotFiniteRule[] =
    "a parameter is not a finite number (null), so the calibration cannot be served";

// Why a scale factor `ratio` times its nominal is implausible, for a unit mix-up of a factor
// close to 9.80665 (g vs m/s²) or 57.3 (deg vs rad); "" when the ratio matches neither.
// `quantity` is "accelerometer" or "gyroscope".
std::string UnitMixupHint(double ratio, const std::string& quantity);

// The `imu`-style triads of parameters.imus / uncertainty.imus (SPEC §7: per IMU an
// "accelerometer" and a "gyroscope" with bias, scale, misalignment and their *_std), judged
// against max_scale_std, max_axis_std (misalignment entries), scale_range and
// implausible_factor (scale against the nominal unit conversions), max_accel_bias_std,
// max_gyro_bias_std, max_accel_bias and max_gyro_bias (SI, bias minus the nominal bias times the
// nominal unit). `label` names the IMUs ("IMU" -> "IMU 0"). Missing limits are not checked.
struct TriadNominal {
  double accel_unit = 1;             // m/s² per reading unit
  double gyro_unit = 1;              // rad/s per reading unit
  std::string accel_text = "m/s^2";  // the configured accel_unit, for messages
  std::string gyro_text = "rad/s";   // the configured gyro_unit
  double accel_bias = 0;             // nominal bias, reading units
  double gyro_bias = 0;
};
// imus_std[i] belongs to imus[i]; an IMU without one is judged undefined.
void JudgeImuTriads(const std::vector<results::ImuTriads>& imus,
                    const std::vector<results::ImuTriadsStd>& imus_std, const TriadNominal& nominal,
                    const AcceptanceLimits& limits, const std::string& label, Verdict* verdict);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_ACCEPTANCE_H_
