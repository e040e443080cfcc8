// HTML building blocks for the report pages: escaping, number formatting, the page skeleton with
// its single embedded stylesheet, status badges.
//
// Pure functions, thread-safe. Anything that came from a user (device serials, sensor names,
// labels, error messages, config values) must pass through EscapeText or EscapeAttr before it is
// written into a page; both also replace invalid UTF-8 and control characters, so the output is
// always well-formed UTF-8.
#ifndef CALIBD_WEB_HTML_H_
#define CALIBD_WEB_HTML_H_

#include <string>
#include <string_view>

#include "base/job_state.h"
#include "base/url.h"
#include "base/utf8.h"

namespace calibd::web {

// From the base library (base/url.h, base/utf8.h).
using ::calibd::SanitizeUtf8;
using ::calibd::UrlEncode;

// Escapes text content: & < > " ' become entities; invalid UTF-8 becomes U+FFFD; control
// characters other than tab and newline are dropped.
std::string EscapeText(std::string_view s);

// Escapes an attribute value (to be written between double quotes). Same mapping as EscapeText;
// tabs and newlines also become character references.
std::string EscapeAttr(std::string_view s);

// ---------------------------------------------------------------------------------------------
// Numbers. All return "–" (en dash) for NaN and "∞"/"−∞" for infinities, and never "-0".

// `sig` significant digits, fixed notation when 1e-3 <= |v| < 1e6, else "1.23e-7".
std::string FormatSig(double v, int sig = 4);

// Fixed `decimals` digits after the point.
std::string FormatFixed(double v, int decimals);

// A length given in metres, shown in µm with `sig` significant digits: "12.3 µm".
std::string FormatMicrometres(double metres, int sig = 3);

// A value with an SI prefix (p n µ m – k M G) chosen so the mantissa is in [1, 1000):
// FormatSI(0.00123, "V") = "1.23 mV". Empty unit allowed.
std::string FormatSI(double v, std::string_view unit, int sig = 3);

// A duration in seconds in plain words: "0.42 s", "3 min 05 s", "2 h 10 min".
std::string FormatDuration(double seconds);

// Parses an ISO-8601-like UTC timestamp ("2026-11-22T04:04:04Z", "2026-11-22 04:04:04",
// fractional seconds and a "+00:00" suffix allowed) or decimal Unix seconds into Unix seconds.
// Returns false when it cannot.
bool ParseTimestamp(std::string_view s, double* unix_seconds);

// ---------------------------------------------------------------------------------------------
// Page pieces.

// The one stylesheet of all pages (system fonts, tabular figures, narrow screens, print).
const char* Stylesheet();

// A status badge: <span class="badge badge-succeeded">succeeded</span>. Unknown statuses get
// class "badge-unknown"; the text is escaped.
std::string StatusBadge(std::string_view status);
inline std::string StatusBadge(JobStatus status) { return StatusBadge(Name(status)); }

// A complete HTML5 document: <!doctype html>, <head> with charset, viewport, escaped <title>,
// the stylesheet; <body> with a header bar (product name, link to /) and `body_html` (already
// safe HTML) inside <main>. `page_class` (e.g. "page-job") goes on <body> for DOM checks.
std::string RenderPage(std::string_view title, std::string_view page_class,
                       std::string_view body_html);

}  // namespace calibd::web

#endif  // CALIBD_WEB_HTML_H_
