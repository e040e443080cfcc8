// Fleets (SPEC §10, issue #27): a product's devices' accepted calibrations of one method, side by
// side. An upload names its product with the config key (or query parameter) `product`; a device's
// fleet membership is the product its latest served calibration of the method was uploaded with
// (a device re-labelled later moves with its next calibration). Per parameter (the numbers in
// the result's `parameters` the method names in Method::FleetParameters, named by their path:
// objects by key, arrays of named objects by their "name", other arrays by index) the distribution
// over the devices (core/fleet_stats.h: median, robust spread, histogram), the devices whose values
// are outliers (robust |z| above the limit), and the fleet's drift: the median per calendar month
// of the calibrations' dates.
#ifndef CALIBD_SERVER_FLEET_H_
#define CALIBD_SERVER_FLEET_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "base/status.h"
#include "storage/store.h"

namespace calibd::server {

// The product as stored: NormalizeSerial's rules (server/device_lookup.h), errors naming the
// field `product`.
Status NormalizeProduct(std::string_view raw, std::string* out);

struct FleetOptions {
  // A device is flagged when one of its parameters' |robust z| exceeds the threshold. By default
  // the threshold is calibrated per parameter (core::RobustZCritical for the n − 1 other devices
  // that know it, at Šidák's level for the number of parameters compared) so that a unit drawn
  // from the fleet's own distribution is flagged with probability outlier_false_alarm. A fixed
  // |z| (outlier_z, with outlier_false_alarm 0) over- or under-flags by fleet size: |z| > 5 flags
  // 15 % of the normal units of an 8-device fleet with 10 parameters, and 0.03 % of a 100-device
  // one (tests/core/fleet_stats_test.cc).
  double outlier_false_alarm = 0.01;  // in [0, 0.5]; 0: outlier_z for every parameter
  double outlier_z = 5;               // > 0: the fixed threshold when outlier_false_alarm is 0
  // A parameter known for fewer devices flags none (its median absolute deviation is too noisy
  // to call a unit an outlier: with 5 devices a normal fleet shows |z| > 3.5 often). >= 3.
  int64_t min_devices = 8;
  int bins = 12;                // histogram bins per parameter (1..100)
  int64_t max_devices = 20000;  // devices scanned at most (each costs one indexed lookup)
};

// The fleet of `product` for `method` (a registered method) as SPEC §10's JSON:
// {"product", "method", "devices", "scanned", "complete", "outlier_false_alarm", "outlier_z" (null
// when calibrated), "min_devices", "members": [{"device", "job_id", "calibrated_at"}],
// "parameters": [{"name", "n", "median", "spread", "min", "max", "threshold" (null below
// min_devices), "histogram": {"edges", "counts"}, "outliers": [{"device", "job_id", "value",
// "z"}]}],
// "outliers": [{"device", "job_id", "parameters": [names], "max_abs_z"}], "drift": [{"month",
// "devices", "median": {name: value}}]}. A product without devices is an empty fleet, not an
// error. Storage errors as they are.
Status FleetJson(storage::Store* store, const std::string& product, const std::string& method,
                 const FleetOptions& options, nlohmann::json* out);

// The gate's fleet rule (acceptance key max_fleet_z, SPEC §10), for a result the method has judged
// (result["verdict"] set). When the limits in force (EffectiveAcceptance of `method` with
// `acceptance_defaults` and the config) set max_fleet_z or max_fleet_false_alarm (α) and the
// config names a `product`, each
// parameter of the result that Method::FleetParameters selects is compared with the accepted
// calibrations of the product's other devices (`device`'s own is left out): robust z = (value −
// median) / spread over them, judged only where the parameter is known for at least
// options.min_devices devices. Each parameter's threshold is max_fleet_z, or
// core::RobustZCritical(n, SidakLevel(α, m)) for its n devices and the m parameters judged,
// whichever is smaller. Any |z| above its threshold rejects the result, one reason naming the
// parameters, their z and thresholds, the rules, the product and the fleet's size;
// diagnostics.fleet gets {"product", "devices", "max_fleet_z", "max_fleet_false_alarm", "judged",
// "parameters": [{"name", "value", "median", "spread", "n", "z", "threshold"}]} (judged false,
// saying why, when the fleet is too small). Storage errors are returned
// as they are and change nothing (the worker retries the job).
Status ApplyFleetGate(storage::Store* store, const std::string& method, const std::string& device,
                      const nlohmann::json& config, const nlohmann::json& acceptance_defaults,
                      const FleetOptions& options, nlohmann::json* result);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_FLEET_H_
