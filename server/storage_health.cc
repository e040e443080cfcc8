#include "server/storage_health.h"

namespace calibd::server {

void StorageHealth::NoteCheck(const std::string& report) {
  std::lock_guard<std::mutex> lock(mu_);
  check_report_ = report;
}

void StorageHealth::Note(const Status& s, const std::string& what, bool write) {
  std::lock_guard<std::mutex> lock(mu_);
  if (s.ok()) {
    damage_.erase(what);
    if (write) disk_full_.clear();
    return;
  }
  if (s.code() == StatusCode::kCorruption) {
    damage_[what] = s.message();
  } else if (s.code() == StatusCode::kIoError && s.reason() == Reason::kDiskFull) {
    disk_full_ = s.message();
  }
}

nlohmann::json StorageHealth::Problems() const {
  std::lock_guard<std::mutex> lock(mu_);
  nlohmann::json out = nlohmann::json::object();
  nlohmann::json damage = nlohmann::json::array();
  if (!check_report_.empty() && check_report_ != "ok") {
    damage.push_back("the database's structure check (quick_check) found: " + check_report_);
  }
  for (const auto& [what, message] : damage_) damage.push_back(what + ": " + message);
  if (!damage.empty()) out["damage"] = std::move(damage);
  if (!disk_full_.empty()) out["disk_full"] = disk_full_;
  return out;
}

}  // namespace calibd::server
