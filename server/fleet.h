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
  // |robust z| above this flags a device's value (> 0). 5, not Iglewicz & Hoaglin's 3.5: the
  // median absolute deviation of a fleet of tens of units is itself uncertain by 20-35 %, and
  // a fleet is screened over every parameter of every unit at once, so 3.5 flags units of a
  // normal fleet (tests/server/fleet_test.cc: a 12-unit fleet showed a noise-only |z| of 4.8).
  // The gate can calibrate its threshold to a family-wise false-alarm rate instead
  // (max_fleet_false_alarm, ApplyFleetGate); the page flags at this fixed |z|.
  double outlier_z = 5;
  // A parameter known for fewer devices flags none (its median absolute deviation is too noisy
  // to call a unit an outlier: with 5 devices a normal fleet shows |z| > 3.5 often). >= 3.
  int64_t min_devices = 8;
  int bins = 12;                // histogram bins per parameter (1..100)
  int64_t max_devices = 20000;  // devices scanned at most (each costs one indexed lookup)
};

// The fleet of `product` for `method` (a registered method) as SPEC §10's JSON:
// {"product", "method", "devices", "scanned", "complete", "outlier_z", "min_devices", "members":
// [{"device", "job_id", "calibrated_at"}], "parameters": [{"name", "n", "median", "spread", "min",
// "max", "histogram": {"edges", "counts"}, "outliers": [{"device", "job_id", "value", "z"}]}],
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
