// The registry of the methods' reports (web/method_report.h): one line per method.
#include "web/method_report.h"
#include "web/reports.h"

namespace calibd::web {

const std::vector<const MethodReport*>& AllMethodReports() {
  // Never destroyed (request threads may render while exit() runs static destructors).
  static const std::vector<const MethodReport*>& reports = *new std::vector<const MethodReport*>{
      &internal::PcaMethodReport(),
      &internal::ArrayMethodReport(),
      &internal::ImuMethodReport(),
      &internal::NoiseMethodReport(),
  };
  return reports;
}

const MethodReport* FindMethodReport(std::string_view method) {
  for (const MethodReport* r : AllMethodReports()) {
    if (method == r->method()) return r;
  }
  return nullptr;
}

}  // namespace calibd::web
