// FailureReason: one entry of the catalog of failure reasons (server/failure_reasons.h): a Reason
// (base/status.h) with a short title and the generic advice. The server's generic reasons have
// their entries in server/failure_reasons.cc; a method lists those of its own reasons
// (core/<name>.h <name>_reason::) in its Method::FailureReasons().
#ifndef CALIBD_METHODS_FAILURE_REASON_H_
#define CALIBD_METHODS_FAILURE_REASON_H_

#include "base/status.h"

namespace calibd::server {

struct FailureReason {
  Reason reason;
  const char* code = "";    // reason.code(): "too_few_positions", stable, documented, snake_case
  const char* title = "";   // "Too few positions": a heading, no final period
  const char* advice = "";  // what to record or set instead: one or two sentences
};

// The entry of `reason` (its code taken from it). Advice says what to record or set instead;
// the method's message (kept beside it) says what it found.
inline FailureReason CatalogEntry(Reason reason, const char* title, const char* advice) {
  return {reason, reason.code(), title, advice};
}

}  // namespace calibd::server

#endif  // CALIBD_METHODS_FAILURE_REASON_H_
