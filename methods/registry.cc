// The registry of calibration methods (methods/registry.h): one line per method.
#include "methods/registry.h"

#include "methods/array/array_method.h"
#include "methods/array/array_report.h"
#include "methods/imu/imu_method.h"
#include "methods/imu/imu_report.h"
#include "methods/mag/mag_method.h"
#include "methods/mag/mag_report.h"
#include "methods/noise/noise_method.h"
#include "methods/noise/noise_report.h"
#include "methods/pca/pca_method.h"
#include "methods/pca/pca_report.h"
#include "methods/thermal/thermal_method.h"
#include "methods/thermal/thermal_report.h"

namespace calibd::server {

const std::vector<MethodDescriptor>& AllMethodDescriptors() {
  // Never destroyed (like every static the request and worker threads read): a thread still
  // running while exit() runs static destructors must not find it freed.
  static const std::vector<MethodDescriptor>& methods = *new std::vector<MethodDescriptor>{
      {&PcaMethod(), &web::internal::PcaMethodReport()},
      {&ArrayMethod(), &web::internal::ArrayMethodReport()},
      {&ImuMethod(), &web::internal::ImuMethodReport()},
      {&NoiseMethod(), &web::internal::NoiseMethodReport()},
      {&ThermalMethod(), &web::internal::ThermalMethodReport()},
      {&MagMethod(), &web::internal::MagMethodReport()},
  };
  return methods;
}

const std::vector<const Method*>& AllMethods() {
  static const std::vector<const Method*>& methods = *[] {
    auto* out = new std::vector<const Method*>;
    for (const MethodDescriptor& d : AllMethodDescriptors()) out->push_back(d.method);
    return out;
  }();
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

namespace calibd::web {

const MethodReport* FindMethodReport(std::string_view method) {
  for (const server::MethodDescriptor& d : server::AllMethodDescriptors()) {
    if (method == d.report->method()) return d.report;
  }
  return nullptr;
}

}  // namespace calibd::web
