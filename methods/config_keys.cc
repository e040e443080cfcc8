// Reading a method's own config keys (methods/config_keys.h).
#include "methods/config_keys.h"

#include <cmath>

#include "methods/acceptance.h"

namespace calibd::server {

Status ConfigKeyError(const std::string& key, const std::string& what) {
  return Status::InvalidInput("config key '" + key + "' " + what)
      .WithField(key)
      .WithReason(Reason::kInvalidConfig);
}

Status ConfigNumber(const nlohmann::json& config, const char* key, double lo, double hi,
                    double* out) {
  auto it = config.find(key);
  if (it == config.end()) return Status::Ok();
  if (!it->is_number() || !std::isfinite(it->get<double>()) || it->get<double>() < lo ||
      it->get<double>() > hi) {
    return ConfigKeyError(key, "must be a number in [" + Fmt(lo) + ", " + Fmt(hi) + "]");
  }
  *out = it->get<double>();
  return Status::Ok();
}

}  // namespace calibd::server
