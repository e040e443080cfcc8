// The array method's references to other jobs (methods/array/array_method.h).
#include <string>

#include "methods/array/array_method.h"
#include "methods/noise/noise_reference.h"
#include "results/json_text.h"
#include "storage/store.h"

namespace calibd::server {

using nlohmann::json;

Status ResolveArrayReferences(storage::Store* store, json* config) {
  if (!config->is_object()) return Status::Ok();
  // accel_noise / gyro_noise: {"job": ID} of a noise job (methods/noise/noise_reference.h).
  Status noise = ResolveNoiseReferences(store, config);
  if (!noise.ok()) return noise;
  auto it = config->find("accelerometer_calibration");
  if (it == config->end() || !it->is_object() || !it->contains("job") || it->contains("result")) {
    return Status::Ok();
  }
  const json& ref = (*it)["job"];
  if (!ref.is_number_integer() || it->size() != 1) {
    return Status::InvalidInput(
               "'accelerometer_calibration' must be a pca result or {\"job\": ID} of a "
               "succeeded pca job")
        .WithField("accelerometer_calibration");
  }
  const int64_t id = ref.get<int64_t>();
  storage::JobInfo job;
  Status s = store->GetJob(id, &job);
  if (s.code() == StatusCode::kNotFound) {
    return Status::InvalidInput("accelerometer_calibration: there is no job " + std::to_string(id))
        .WithField("accelerometer_calibration");
  }
  if (!s.ok()) return s;
  if (job.method != "pca" || job.status != JobStatus::kSucceeded) {
    return Status::InvalidInput("accelerometer_calibration: job " + std::to_string(id) + " is a " +
                                Name(job.status) + " " + job.method +
                                " job; it must be a succeeded pca job")
        .WithField("accelerometer_calibration");
  }
  if (!job.served()) {
    // The gate applies to calibrations that feed other calibrations too.
    return Status::InvalidInput(
               "accelerometer_calibration: job " + std::to_string(id) + " is " + Name(job.state) +
               (job.state == ServeState::kRejected ? " by the acceptance gate" : std::string()) +
               " (see /jobs/" + std::to_string(id) +
               "); use an accepted pca calibration, or accept this one with a "
               "reason first")
        .WithField("accelerometer_calibration");
  }
  json result;
  s = results::ParseJsonText(job.result_json, "result of job " + std::to_string(id), &result);
  if (!s.ok()) return Status::Internal("stored result is not JSON");
  *it = json{{"job", id}, {"result", std::move(result)}};
  return Status::Ok();
}

}  // namespace calibd::server
