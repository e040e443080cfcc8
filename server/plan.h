// Planning a calibration (SPEC §10, issue #27 item 1): POST /api/v1/plan and `calibd plan` share
// PlanJson; the numbers are the method's own (Method::Plan, methods/plan.h).
#ifndef CALIBD_SERVER_PLAN_H_
#define CALIBD_SERVER_PLAN_H_

#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "web/pages.h"

namespace calibd::storage {
class Store;  // storage/store.h
}  // namespace calibd::storage

namespace calibd::server {

// The plan of a request {"method": NAME, "config": {...}, "protocol": {...}} (config optional,
// its `method` may be left out; its references {"job": ID} resolved by the caller), with
// `acceptance_defaults` the server-wide limits per method (null: built-in): the method's answer
// (Method::Plan) {"method", "protocol", "uncertainty", "undetermined", "suggested", "notes", ...}
// plus "limits" (the gate limits in force). kInvalidInput naming the field ("method",
// "config.<key>", "protocol.orientations[3]"), including a method without a plan yet.
// Deterministic; thread-safe.
Status PlanJson(const nlohmann::json& request, const nlohmann::json& acceptance_defaults,
                nlohmann::json* out);

// The /plan page's view from its form (GET query: method, config (JSON text), o (ticked candidate
// directions, repeated), orientations (names or [x, y, z] separated by spaces), static_duration,
// rate, rotation_duration): the form as sent (defaults when empty) and, once a method is given,
// PlanJson's answer or its error. The config's {"job": ID} references are resolved in `store`.
web::PlanView PlanPageView(const std::multimap<std::string, std::string>& params,
                           storage::Store* store, const nlohmann::json& acceptance_defaults);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_PLAN_H_
