// The registry of calibration methods (server/method.h): one line per method.
#include "server/array_method.h"
#include "server/imu_method.h"
#include "server/method.h"
#include "server/noise_method.h"
#include "server/pca_method.h"

namespace calibd::server {

const std::vector<const Method*>& AllMethods() {
  // Never destroyed (like every static the request and worker threads read): a thread still
  // running while exit() runs static destructors must not find it freed.
  static const std::vector<const Method*>& methods = *new std::vector<const Method*>{
      &PcaMethod(),
      &ArrayMethod(),
      &ImuMethod(),
      &NoiseMethod(),
  };
  return methods;
}

const Method* FindMethod(std::string_view name) {
  for (const Method* m : AllMethods()) {
    if (name == m->name()) return m;
  }
  return nullptr;
}

std::string MethodNamesForMessage() {
  const auto& methods = AllMethods();
  std::string out;
  for (size_t i = 0; i < methods.size(); ++i) {
    if (i > 0) out += i + 1 == methods.size() ? " or " : ", ";
    out += std::string("\"") + methods[i]->name() + "\"";
  }
  return out;
}

}  // namespace calibd::server
