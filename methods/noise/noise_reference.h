// `accel_noise` / `gyro_noise` as {"job": ID} of a succeeded noise job (SPEC §7), in imu and
// array configs over HTTP.
//
// At enqueue (upload or POST /jobs), ResolveNoiseReferences replaces each such reference by
// {"job": ID, "sigma": σ, "white_noise": N, "random_walk": K or null, "rate": f, "channels": [...]}
// taken from that job's
// stored result, so the queued job is self-contained (a later noise job cannot change it) and
// says which job it used. σ is the per-sample standard deviation the methods take:
// σ = N · √f, with N the largest white-noise density (unit/√Hz, SI) over that sensor type's
// channels of the noise log and f that log's sample rate — the per-sample noise of the sensor at
// the noise log's rate and filter settings, so the calibration log should be recorded the same
// way (the same output data rate).
//
// The methods read a noise level with ReadNoiseLevel: a plain number (in the method's own units)
// or a resolved reference (σ in SI); an unresolved {"job": ID} (e.g. offline, where there is no
// job history) is an error saying so.
#ifndef CALIBD_SERVER_NOISE_REFERENCE_H_
#define CALIBD_SERVER_NOISE_REFERENCE_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>

#include "base/status.h"
#include "storage/store.h"

namespace calibd::server {

// kInvalidInput naming the key: not an integer id, no such job, not a succeeded noise job, a job
// whose stored result does not read as results::NoiseResult (methods/noise/noise_result.h: the
// message names the path of the problem, e.g. a newer schema_version), or a job whose log does not
// show the white noise of that sensor type; storage errors as they are. Leaves numbers and
// already-resolved references alone. Called by the methods that take noise levels (imu and array:
// their Method::ResolveReferences); `config` not yet validated.
Status ResolveNoiseReferences(storage::Store* store, nlohmann::json* config);

struct NoiseLevel {
  double value = 0;            // the number as given, or σ of a reference (SI)
  bool si = false;             // value is SI (from a noise job), not in the config's units
  std::optional<int64_t> job;  // the noise job it came from
};

// Reads config[key] when present (std::nullopt when absent or null): a finite number > 0, or a
// resolved reference. kInvalidInput naming the key otherwise.
Status ReadNoiseLevel(const nlohmann::json& config, const char* key,
                      std::optional<NoiseLevel>* out);

// Kalibr's figures of config[key] when it is a resolved reference (SI; the largest axis; NaN for
// a figure the noise job did not show); nullopt for a number, nothing, or an unresolved reference.
struct NoiseFigures {
  std::optional<int64_t> job;
  double white_noise = 0;  // unit/√Hz
  double random_walk = 0;  // unit/s/√Hz
};
std::optional<NoiseFigures> ReadNoiseFigures(const nlohmann::json& config, const char* key);

// {"accelerometer": ID or null, "gyroscope": ID or null}: the noise jobs a config's resolved
// references came from, for the result's diagnostics.noise_jobs.
nlohmann::json NoiseJobsJson(const nlohmann::json& config);
// {"accelerometer": {"job", "white_noise", "random_walk"} or null, "gyroscope": ...}: Kalibr's
// figures (SI; the largest axis) of the resolved references, for exports of the result.
nlohmann::json NoiseModelJson(const nlohmann::json& config);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_NOISE_REFERENCE_H_
