#include "base/job_state.h"

#include <cstddef>
#include <ostream>

namespace calibd {
namespace {

// The names of an enum's values in the order of the enum (its underlying values 0, 1, ...).
template <typename E, size_t N>
bool ParseName(std::string_view text, const char* const (&names)[N], E* out) {
  for (size_t i = 0; i < N; ++i) {
    if (text == names[i]) {
      *out = static_cast<E>(i);
      return true;
    }
  }
  return false;
}

constexpr const char* kJobStatusNames[] = {"queued", "running", "succeeded", "failed"};
constexpr const char* kGateVerdictNames[] = {"", "accepted", "rejected"};
constexpr const char* kDecisionNames[] = {"", "revoked", "accepted"};
constexpr const char* kServeStateNames[] = {"", "accepted", "rejected", "revoked"};

}  // namespace

const char* Name(JobStatus status) { return kJobStatusNames[static_cast<int>(status)]; }
const char* Name(GateVerdict verdict) { return kGateVerdictNames[static_cast<int>(verdict)]; }
const char* Name(Decision decision) { return kDecisionNames[static_cast<int>(decision)]; }
const char* Name(ServeState state) { return kServeStateNames[static_cast<int>(state)]; }

bool Parse(std::string_view text, JobStatus* out) { return ParseName(text, kJobStatusNames, out); }
bool Parse(std::string_view text, GateVerdict* out) {
  return ParseName(text, kGateVerdictNames, out);
}
bool Parse(std::string_view text, Decision* out) { return ParseName(text, kDecisionNames, out); }
bool Parse(std::string_view text, ServeState* out) {
  return ParseName(text, kServeStateNames, out);
}

std::ostream& operator<<(std::ostream& os, JobStatus v) { return os << Name(v); }
std::ostream& operator<<(std::ostream& os, GateVerdict v) { return os << Name(v); }
std::ostream& operator<<(std::ostream& os, Decision v) { return os << Name(v); }
std::ostream& operator<<(std::ostream& os, ServeState v) { return os << Name(v); }

}  // namespace calibd
