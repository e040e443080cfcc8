#include "methods/noise/noise_reference.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "methods/noise/noise_result.h"
#include "results/json_text.h"

namespace calibd::server {

using nlohmann::json;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Status KeyError(const std::string& key, const std::string& message) {
  return Status::InvalidInput("config key '" + key + "': " + message).WithField(key);
}

Status Resolve(storage::Store* store, const std::string& key, json* value) {
  const json& ref = (*value)["job"];
  if (!ref.is_number_integer() || ref.get<int64_t>() <= 0 || value->size() != 1) {
    return KeyError(key, "must be a number or {\"job\": ID} of a succeeded noise job");
  }
  const int64_t id = ref.get<int64_t>();
  storage::JobInfo job;
  Status s = store->GetJob(id, &job);
  if (s.code() == StatusCode::kNotFound)
    return KeyError(key, "there is no job " + std::to_string(id));
  if (!s.ok()) return s;
  if (job.method != "noise" || job.status != JobStatus::kSucceeded) {
    return KeyError(key, "job " + std::to_string(id) + " is a " + Name(job.status) + " " +
                             job.method + " job; it must be a succeeded noise job");
  }
  json doc;
  if (!results::ParseJsonText(job.result_json, "result", &doc).ok()) {
    return Status::Internal("stored result is not JSON");
  }
  // The noise job's result, typed: a result this calibd cannot read (e.g. a newer schema) is the
  // user's reference that does not work, named with the path of the problem.
  results::NoiseResult result;
  s = results::FromJson(doc, &result);
  if (!s.ok()) {
    return KeyError(key, "noise job " + std::to_string(id) + " cannot be used: " + s.message());
  }
  const char prefix = key == "accel_noise" ? 'a' : 'g';
  const double rate = result.diagnostics.rate;
  double worst = -1, worst_walk = -1;
  bool walk_seen = true;  // every channel of the type shows its random walk
  json channels = json::array();
  for (const results::NoiseChannelParameters& c : result.channels) {
    if (c.name.empty() || c.name[0] != prefix) continue;
    if (!std::isfinite(c.white_noise)) {
      return KeyError(
          key, "noise job " + std::to_string(id) + " does not show the white noise of " + c.name);
    }
    channels.push_back({{"name", c.name},
                        {"white_noise", c.white_noise},
                        {"random_walk", results::Num(c.random_walk)}});
    worst = std::max(worst, c.white_noise);
    if (std::isfinite(c.random_walk)) {
      worst_walk = std::max(worst_walk, c.random_walk);
    } else {
      walk_seen = false;
    }
  }
  if (worst <= 0 || !(rate > 0) || !std::isfinite(rate)) {
    return KeyError(key, std::string("noise job ") + std::to_string(id) + " has no " +
                             (prefix == 'a' ? "accelerometer" : "gyroscope") + " channels");
  }
  *value = {{"job", id},
            {"sigma", worst * std::sqrt(rate)},
            {"white_noise", worst},
            {"random_walk", walk_seen && worst_walk > 0 ? json(worst_walk) : json()},
            {"rate", rate},
            {"channels", channels}};
  return Status::Ok();
}

}  // namespace

Status ResolveNoiseReferences(storage::Store* store, json* config) {
  if (!config->is_object()) return Status::Ok();
  for (const char* key : {"accel_noise", "gyro_noise"}) {
    auto it = config->find(key);
    if (it == config->end() || !it->is_object() || it->contains("sigma")) continue;
    Status s = Resolve(store, key, &*it);
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Status ReadNoiseLevel(const json& config, const char* key, std::optional<NoiseLevel>* out) {
  out->reset();
  auto it = config.find(key);
  if (it == config.end() || it->is_null()) return Status::Ok();
  NoiseLevel level;
  if (it->is_number()) {
    level.value = it->get<double>();
  } else if (it->is_object() && it->contains("job")) {
    auto sigma = it->find("sigma");
    const json& job = (*it)["job"];
    if (sigma == it->end()) {
      return KeyError(key,
                      "{\"job\": ID} is resolved by the server when the job is queued (over "
                      "HTTP); offline, give the noise level as a number");
    }
    if (!job.is_number_integer() || !sigma->is_number()) {
      return KeyError(key, "a resolved noise reference needs an integer \"job\" and a \"sigma\"");
    }
    level.value = sigma->get<double>();
    level.si = true;
    level.job = job.get<int64_t>();
  } else {
    return KeyError(key, "must be a number > 0 or {\"job\": ID} of a succeeded noise job");
  }
  if (!std::isfinite(level.value) || !(level.value > 0)) {
    // 0 is no noise level (it would weigh the samples infinitely); where a method can estimate
    // it from the statics (imu, array model full), leaving the key out does that.
    return KeyError(key,
                    "must be a finite number > 0 (leave it out to have it estimated from the "
                    "statics, where the method can: imu, array model full)");
  }
  *out = level;
  return Status::Ok();
}

std::optional<NoiseFigures> ReadNoiseFigures(const json& config, const char* key) {
  auto it = config.find(key);
  if (it == config.end() || !it->is_object() || !it->contains("sigma")) return std::nullopt;
  auto number = [&](const char* member) {
    auto m = it->find(member);
    return m != it->end() && m->is_number() ? m->get<double>() : kNaN;
  };
  NoiseFigures f;
  if (auto job = it->find("job"); job != it->end() && job->is_number_integer()) {
    f.job = job->get<int64_t>();
  }
  f.white_noise = number("white_noise");
  f.random_walk = number("random_walk");
  return f;
}

json NoiseModelJson(const json& config) {
  json out = {{"accelerometer", nullptr}, {"gyroscope", nullptr}};
  for (auto [key, sensor] : {std::pair<const char*, const char*>{"accel_noise", "accelerometer"},
                             {"gyro_noise", "gyroscope"}}) {
    if (std::optional<NoiseFigures> f = ReadNoiseFigures(config, key)) {
      out[sensor] = {{"job", f->job ? json(*f->job) : json()},
                     {"white_noise", results::Num(f->white_noise)},
                     {"random_walk", results::Num(f->random_walk)}};
    }
  }
  return out;
}

json NoiseJobsJson(const json& config) {
  json out = {{"accelerometer", nullptr}, {"gyroscope", nullptr}};
  for (auto [key, sensor] : {std::pair<const char*, const char*>{"accel_noise", "accelerometer"},
                             {"gyro_noise", "gyroscope"}}) {
    auto it = config.find(key);
    if (it != config.end() && it->is_object() && it->contains("job") &&
        (*it)["job"].is_number_integer()) {
      out[sensor] = (*it)["job"];
    }
  }
  return out;
}

}  // namespace calibd::server
