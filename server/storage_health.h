// StorageHealth: what the server knows about the state of its storage, for /healthz. Fed by the
// structure check (Store::QuickCheck, at start and on a schedule) and by what requests and jobs
// meet: damaged stored bytes (kCorruption), a full disk (Reason::kDiskFull). Thread-safe.
#ifndef CALIBD_SERVER_STORAGE_HEALTH_H_
#define CALIBD_SERVER_STORAGE_HEALTH_H_

#include <cstdint>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"

namespace calibd::server {

class StorageHealth {
 public:
  // The report of a structure check: "ok", or the damage found (replaces the previous report).
  void NoteCheck(const std::string& report);
  // The outcome of a storage call about `what` ("recording 3", "the result of job 5"):
  //   kCorruption: `what` is damaged (kept until a sound read or rewrite of it: Note OK);
  //   kIoError with Reason::kDiskFull: the disk is full (kept until a write succeeds);
  //   OK: a sound read of `what` (its damage is forgotten: repaired) and, when `write`, a
  //   successful write (the disk is not full).
  // Other failures (busy, unreachable) are not remembered: /healthz sees those itself.
  void Note(const Status& s, const std::string& what, bool write);
  // The problems now: {"damage": [...], "disk_full": "..."} with only those present, or an empty
  // object when there are none.
  nlohmann::json Problems() const;

 private:
  mutable std::mutex mu_;
  std::string check_report_;                   // "" before the first check, "ok", or a report
  std::map<std::string, std::string> damage_;  // what -> the message
  std::string disk_full_;                      // the last full-disk message, "" none
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_STORAGE_HEALTH_H_
