// ProcessInstance: this process's identity among the calibd processes that share one database
// folder, its own staging folder, and the detection of dead processes.
//
// Every process holds an exclusive flock(2) on <staging root>/<host>_<pid>_<start>.lock for its
// whole life and stages uploads in <staging root>/<host>_<pid>_<start>/. The kernel drops a
// flock when its process dies, kill -9 included, so a lock file of this host that can be locked
// belongs to a dead process: its jobs can be taken back at once (rather than after their lease
// runs out) and its staging folder removed. Processes on other hosts are never judged (their
// leases expire as usual). Staging is per process: starting a process never removes the files
// of another live one.
#ifndef CALIBD_SERVER_INSTANCE_H_
#define CALIBD_SERVER_INSTANCE_H_

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "base/status.h"

namespace calibd::server {

class ProcessInstance {
 public:
  // Creates the staging root if needed, this process's lock file (locked) and staging folder.
  static Status Create(const std::filesystem::path& staging_root,
                       std::unique_ptr<ProcessInstance>* out);
  ~ProcessInstance();  // removes this process's staging folder and lock file
  ProcessInstance(const ProcessInstance&) = delete;
  ProcessInstance& operator=(const ProcessInstance&) = delete;

  // "host:pid:start_ns": unique among all processes ever run on the database; the prefix of this
  // process's worker (lease holder) ids.
  const std::string& id() const { return id_; }
  const std::filesystem::path& staging_dir() const { return staging_dir_; }

  // Finds the dead processes of this host. For each, calls take_back(its id); when that returns
  // OK, removes the dead process's staging folder and lock file (otherwise they stay, and the
  // next call tries again). Also removes staging files of calibd versions before per-process
  // staging that are older than a day. Returns the number of dead processes handled.
  int ReapDead(const std::function<Status(const std::string& id)>& take_back);

 private:
  ProcessInstance() = default;
  std::filesystem::path root_, staging_dir_, lock_path_;
  std::string host_, id_;
  int lock_fd_ = -1;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_INSTANCE_H_
