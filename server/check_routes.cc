// GET /api/v1/recordings/{id}/check?method=M&<config keys> | ?job=ID (SPEC §10,
// server/recording_check.h): 404 for an unknown recording or job, 400 naming a bad method or
// config key, 422 for a recording that is not an inertial log or over the job memory budget.
#include <string>

#include "server/recording_check.h"
#include "server/service_impl.h"

namespace calibd::server {

void Service::Impl::HandleCheck(const httplib::Request& req, httplib::Response& res) {
  const std::string text = req.matches[1];
  if (text.empty() || text.size() > 18 ||
      text.find_first_not_of("0123456789") != std::string::npos || std::stoll(text) <= 0) {
    SendError(res, 404, "not_found", "no such recording");
    return;
  }
  CheckRequest request;
  request.recording_id = std::stoll(text);
  request.job_memory_bytes = job_memory_bytes;
  request.cache = column_cache.get();
  Status s = ParseCheckQuery(req.params, store.get(), &request);
  if (!s.ok()) return (void)SendStatus(res, s);
  nlohmann::json body;
  s = ComputeCheck(store.get(), request, &body);
  if (!s.ok()) return (void)SendStatus(res, s);
  res.set_content(JsonBody(body), "application/json");
}

}  // namespace calibd::server
