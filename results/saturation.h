// diagnostics.saturation of the methods that read raw triads (imu, array, noise): per channel the
// clip level found in the data or configured, the samples pinned there, and what the method did
// with them (core/saturation.h finds them).
//
// {"policy": "dropped" | "refused", "samples": <samples with any channel pinned>,
//  "channels": [{"name": "g3_x", "source": "data" | "config", "unit": "deg/s",
//                "low": -1998.05 | null, "high": 1997.99 | null,
//                "pinned_low": 200, "pinned_high": 186}]}
// Only channels with a pinned sample are listed; low/high null: no level on that side. An
// extension of SPEC §4 (absent from results of an earlier calibd, and when nothing is pinned).
#ifndef CALIBD_RESULTS_SATURATION_H_
#define CALIBD_RESULTS_SATURATION_H_

#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "results/json_reader.h"

namespace calibd::results {

struct SaturationChannel {
  std::string name;                                       // "g3_x"
  std::string source;                                     // "data" | "config"
  std::string unit;                                       // of low and high
  double low = -std::numeric_limits<double>::infinity();  // -inf: none (null)
  double high = std::numeric_limits<double>::infinity();  // +inf: none (null)
  int64_t pinned_low = 0, pinned_high = 0;
};

struct SaturationDiagnostics {
  std::string policy;   // "dropped" (from the fit; statics: their window) | "refused" (noise)
  int64_t samples = 0;  // samples (rows of the log) with any channel pinned
  std::vector<SaturationChannel> channels;
};

nlohmann::json ToJson(const SaturationDiagnostics& s);
// Reads member "saturation" of `diagnostics` when present (else *out stays nullopt).
void ReadSaturation(const JsonReader& diagnostics, std::optional<SaturationDiagnostics>* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_SATURATION_H_
