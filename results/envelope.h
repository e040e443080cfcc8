// The part of every result document that is the same for all methods (SPEC §4): method, the
// schema version, model, the acceptance gate's verdict, warnings, and whether it is a usable
// result or a failed run's partial diagnostics.
//
// Versioning: every result carries "schema_version" (an extension of SPEC §4), the version of its
// method's typed schema (results/<name>_result.h, kSchemaVersion). A reader accepts every version
// up to its own; a document without the key is version 1 (results stored before the key existed
// have version 1's shape). A newer version than the reader knows is refused naming both, so an old
// calibd never misreads a newer result. Raise a method's version when a field changes meaning or
// goes away; adding a field a reader may ignore needs no new version.
#ifndef CALIBD_RESULTS_ENVELOPE_H_
#define CALIBD_RESULTS_ENVELOPE_H_

#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/job_state.h"
#include "results/json_reader.h"

namespace calibd::results {

// The acceptance gate's answer as stored in a result ("verdict"; methods/acceptance.h writes it).
struct StoredVerdict {
  GateVerdict status = GateVerdict::kNone;  // kAccepted | kRejected (never kNone when present)
  std::vector<std::string> reasons;         // one per failed rule, in words; empty when accepted
  // The limits in force: key -> value, nullopt for "no limit".
  std::map<std::string, std::optional<double>> limits;
};

struct Envelope {
  std::string method;      // the registered method's name (methods/registry.h)
  int schema_version = 1;  // the method's typed schema version the document was written in
  // false: a failed run's partial diagnostics ({"method", "usable": false, "diagnostics",
  // "warnings"}): no model, parameters or uncertainty. Written only when false.
  bool usable = true;
  std::string model;                     // the equation (usable results)
  std::optional<StoredVerdict> verdict;  // absent until the gate has judged the result
  std::vector<std::string> warnings;
};

// Reads the envelope of a result of `method` whose typed schema is at version `newest`: the
// method must match, schema_version (absent: 1) must be within 1..newest, model is required
// unless usable is false. Problems go to `r` (JsonReader::status()).
void ReadEnvelope(const JsonReader& r, const char* method, int newest, Envelope* out);

// Writes the envelope's keys into the object `*out` (schema_version as `version`: a writer always
// writes its newest; "usable" only when false; "verdict" only when present).
void WriteEnvelope(const Envelope& e, int version, nlohmann::json* out);

// A failed run's partial document trimmed by the server to fit the store
// (server/failure_reasons.h): its "trimmed" note as stored, and the diagnostics members it names
// as dropped ("diagnostics" itself when only the envelope was kept). Nothing when not trimmed.
void ReadTrimmed(const JsonReader& r, std::optional<nlohmann::json>* trimmed,
                 std::vector<std::string>* dropped);
// Whether `key` is in `keys`.
bool ContainsKey(const std::vector<std::string>& keys, const char* key);
// Whether diagnostics member `key` of `d` is one the trimming dropped: listed, and absent (or
// null, in documents trimmed before the members were left out).
bool DroppedMember(const JsonReader& d, const std::vector<std::string>& dropped, const char* key);

// The verdict as the gate writes it: {"status", "reasons", "limits"}.
nlohmann::json VerdictJson(const StoredVerdict& v);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_ENVELOPE_H_
