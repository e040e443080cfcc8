// Small HTTP helpers shared by the routes: JSON errors (SPEC §5), status mapping, route labels
// for metrics, and the OpenAPI document.
#ifndef CALIBD_SERVER_HTTP_UTIL_H_
#define CALIBD_SERVER_HTTP_UTIL_H_

#include <httplib.h>
// httplib.h includes <resolv.h>, whose macro `_res` breaks Eigen's headers (a parameter there is
// named _res). We never use the resolver state directly.
#ifdef _res
#undef _res
#endif

#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "base/url.h"

namespace calibd::storage {
class Store;
}

namespace calibd::server {

using ::calibd::UrlEncode;  // base/url.h

// "HOST:PORT" or "[V6]:PORT" -> parts. False when malformed (port must be 0..65535).
bool SplitHostPort(const std::string& listen, std::string* host, int* port);

// Writes {"error": {"code", "message", ["line", "column", "field"]}} with `status`.
void SendError(httplib::Response& res, int status, const std::string& code,
               const std::string& message, int64_t line = 0, int64_t column = 0,
               const std::string& field = {});
// `value` as pretty JSON text with a final newline; invalid UTF-8 in strings is replaced (never
// throws).
std::string JsonBody(const nlohmann::json& value);
// The HTTP status for a Status code: 400 invalid input, 422 not determinable, 404, 409 conflict,
// 413, 415, 503 busy or I/O error, 507 a full disk (Reason::kDiskFull), 500 otherwise (with the
// message only for damaged storage). Writes the error body and returns the status.
int SendStatus(httplib::Response& res, const Status& status);

std::string ToLower(std::string s);
// The route pattern of a path, for metric labels: ids and serials replaced by {id} / {serial},
// unknown paths collapsed to "other" (so hostile paths cannot grow the label set).
std::string RouteLabel(const std::string& path);
// Printable ASCII only, at most 200 characters: safe for a log line.
std::string SanitizeForLog(const std::string& s);
// The server's exception handler (a route threw `error`): 500 {"code": "internal"} with a
// generic message, never the exception's text (it may reveal internals); the operator's log
// (stderr, one write) has the request's method and path and what was thrown.
void AnswerException(const httplib::Request& req, httplib::Response& res, std::exception_ptr error);
// True when an If-None-Match header value matches `etag` (a list, or "*").
bool IfNoneMatchHits(const std::string& header, const std::string& etag);
// "GET, HEAD" style list of the methods a known path allows; "" for an unknown path.
std::string AllowedMethods(const std::string& path);
// The OpenAPI 3 description of the HTTP API.
const nlohmann::json& OpenApiDocument();
// The HTML pages (SPEC §5): /, /jobs/{id}, /devices/{serial}. `token_required`: writes need the
// server's token (the job page's cancel form asks for it).
void RegisterHtmlRoutes(httplib::Server* http, storage::Store* store, bool token_required);
// Sends a page with the pages' headers (no-cache, the Content-Security-Policy, nosniff).
void SendPage(httplib::Response& res, int status, std::string html);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_HTTP_UTIL_H_
