// The registry of calibration methods: one MethodDescriptor per method, one line each in
// methods/registry.cc. Everything outside methods/<name>/ finds a method here, by name: the CLI's
// `calibrate` and `simulate`, the upload, job and export routes, the job list filters, the
// OpenAPI document, the acceptance defaults, and the pages (report sections, key figures, drift,
// download links).
//
// Adding a method: the folder methods/<name>/ (see methods/method.h) and one line in
// AllMethodDescriptors().
#ifndef CALIBD_METHODS_REGISTRY_H_
#define CALIBD_METHODS_REGISTRY_H_

#include <string>
#include <string_view>
#include <vector>

#include "methods/method.h"
#include "web/method_report.h"

namespace calibd::server {

// One method: what the server runs (config, run, gate, exports, simulate) and what the pages show
// of its results (report section, partial report, key figures, drift). Both name the same method.
struct MethodDescriptor {
  const Method* method;
  const web::MethodReport* report;
};

// Every method, in the order users see them. Never empty; the pointers live for the process.
const std::vector<MethodDescriptor>& AllMethodDescriptors();
// The methods alone, in the same order.
const std::vector<const Method*>& AllMethods();
// The method named `name`, or null.
const Method* FindMethod(std::string_view name);
// "\"pca\", \"array\" or ..." for messages.
std::string MethodNamesForMessage();

}  // namespace calibd::server

namespace calibd::web {

// The report of `method`, or null.
const MethodReport* FindMethodReport(std::string_view method);

}  // namespace calibd::web

#endif  // CALIBD_METHODS_REGISTRY_H_
