// GET /api/v1/products/{product}/fleet?method=M[&false_alarm=A | &outlier_z=Z] (SPEC §10,
// server/fleet.h): the threshold calibrated to A (default 0.01), or a fixed robust |z|.
#include <cmath>
#include <string>

#include "methods/registry.h"
#include "server/fleet.h"
#include "server/service_impl.h"

namespace calibd::server {

void Service::Impl::HandleFleet(const httplib::Request& req, httplib::Response& res) {
  std::string product;
  if (Status s = NormalizeProduct(std::string(req.matches[1]), &product); !s.ok()) {
    return (void)SendStatus(res, s);
  }
  FleetOptions options;
  std::string method;
  for (const auto& [key, value] : req.params) {
    if (key == "method") {
      method = value;
    } else if (key == "outlier_z") {
      char* end = nullptr;
      const double z = std::strtod(value.c_str(), &end);
      if (value.empty() || end != value.c_str() + value.size() || !(z > 0) || !std::isfinite(z)) {
        return (void)SendStatus(
            res, Status::InvalidInput("outlier_z must be a number > 0 (a robust z; default 5)")
                     .WithField("outlier_z"));
      }
      options.outlier_z = z;
      options.outlier_false_alarm = 0;
    } else if (key == "false_alarm") {
      char* end = nullptr;
      const double a = std::strtod(value.c_str(), &end);
      if (value.empty() || end != value.c_str() + value.size() || !(a > 0 && a <= 0.5)) {
        return (void)SendStatus(
            res, Status::InvalidInput("false_alarm must be a number in (0, 0.5] (the probability "
                                      "that a unit like the others is flagged; default 0.01)")
                     .WithField("false_alarm"));
      }
      options.outlier_false_alarm = a;
    } else {
      return (void)SendStatus(res,
                              Status::InvalidInput("unknown query parameter '" + key.substr(0, 64) +
                                                   "' (known: method, false_alarm, outlier_z)")
                                  .WithField(key.substr(0, 64)));
    }
  }
  if (FindMethod(method) == nullptr) {
    return (void)SendStatus(
        res, Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method"));
  }
  nlohmann::json body;
  if (Status s = FleetJson(store.get(), product, method, options, &body); !s.ok()) {
    return (void)SendStatus(res, s);
  }
  res.set_content(JsonBody(body), "application/json");
}

}  // namespace calibd::server
