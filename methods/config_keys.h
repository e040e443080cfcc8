// Reading a method's own config keys (Method::ValidateConfig, Run): errors that name the key, for
// the methods whose messages read "config key 'K' ...".
#ifndef CALIBD_METHODS_CONFIG_KEYS_H_
#define CALIBD_METHODS_CONFIG_KEYS_H_

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"

namespace calibd::server {

// kInvalidInput "config key '<key>' <what>", field `key`, reason kInvalidConfig.
Status ConfigKeyError(const std::string& key, const std::string& what);

// A finite number at config[key] within [lo, hi] into *out; absent leaves *out (the default).
// Else ConfigKeyError naming the range.
Status ConfigNumber(const nlohmann::json& config, const char* key, double lo, double hi,
                    double* out);

}  // namespace calibd::server

#endif  // CALIBD_METHODS_CONFIG_KEYS_H_
