// The vocabulary of a calibration job's life, shared by storage (which stores it as text),
// web (which shows it) and the server (which writes it into JSON): enums, each with its one
// spelling. Name() gives the text of SPEC §5 and the database columns; Parse() reads it back.
#ifndef CALIBD_BASE_JOB_STATE_H_
#define CALIBD_BASE_JOB_STATE_H_

#include <iosfwd>
#include <string_view>

namespace calibd {

// A job's place in the queue: queued -> running -> succeeded | failed (storage/store.h).
enum class JobStatus { kQueued, kRunning, kSucceeded, kFailed };
// The acceptance gate's verdict of a succeeded job's result; kNone before a result.
enum class GateVerdict { kNone, kAccepted, kRejected };
// A person's later decision on a result; kNone when nobody decided.
enum class Decision { kNone, kRevoked, kAccepted };
// What follows for a result (the decision, else the verdict): kAccepted results are served as a
// device's calibration; kNone for a job without a result.
enum class ServeState { kNone, kAccepted, kRejected, kRevoked };

// "queued" | "running" | "succeeded" | "failed".
const char* Name(JobStatus status);
// "" (kNone) | "accepted" | "rejected".
const char* Name(GateVerdict verdict);
// "" (kNone) | "revoked" | "accepted".
const char* Name(Decision decision);
// "" (kNone) | "accepted" | "rejected" | "revoked".
const char* Name(ServeState state);

// The value Name() spells `text` as: true and *out set, or false (out untouched). The empty
// text parses as kNone where there is one.
bool Parse(std::string_view text, JobStatus* out);
bool Parse(std::string_view text, GateVerdict* out);
bool Parse(std::string_view text, Decision* out);
bool Parse(std::string_view text, ServeState* out);

// Writes Name(value) (test failure messages, logs); kNone writes "".
std::ostream& operator<<(std::ostream& os, JobStatus v);
std::ostream& operator<<(std::ostream& os, GateVerdict v);
std::ostream& operator<<(std::ostream& os, Decision v);
std::ostream& operator<<(std::ostream& os, ServeState v);

}  // namespace calibd

#endif  // CALIBD_BASE_JOB_STATE_H_
