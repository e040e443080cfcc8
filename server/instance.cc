#include "server/instance.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <chrono>
#include <system_error>

namespace calibd::server {

namespace fs = std::filesystem;

namespace {

std::string HostName() {
  char name[256] = {};
  if (gethostname(name, sizeof name - 1) != 0 || name[0] == '\0') return "host";
  std::string host(name);
  // File-name safe: host names are [A-Za-z0-9.-]; anything else (and '_', our separator) -> '-'.
  for (char& c : host) {
    if (!isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-') c = '-';
  }
  return host;
}

}  // namespace

Status ProcessInstance::Create(const fs::path& staging_root,
                               std::unique_ptr<ProcessInstance>* out) {
  std::unique_ptr<ProcessInstance> p(new ProcessInstance());
  p->root_ = staging_root;
  p->host_ = HostName();
  const std::string pid = std::to_string(getpid());
  const std::string start =
      std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
  p->id_ = p->host_ + ":" + pid + ":" + start;
  const std::string stem = p->host_ + "_" + pid + "_" + start;
  std::error_code ec;
  fs::create_directories(staging_root, ec);
  if (ec) return Status::IoError("cannot create " + staging_root.string() + ": " + ec.message());
  // Locked under a temporary name, then renamed (the lock stays with the file): no other
  // process ever sees this lock file unlocked and takes it for a dead one.
  p->lock_path_ = staging_root / (stem + ".lock");
  const fs::path temporary = staging_root / (stem + ".lock.tmp");
  p->lock_fd_ = ::open(temporary.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (p->lock_fd_ < 0 || ::flock(p->lock_fd_, LOCK_EX | LOCK_NB) != 0 ||
      ::rename(temporary.c_str(), p->lock_path_.c_str()) != 0) {
    return Status::IoError("cannot create and lock " + p->lock_path_.string());
  }
  p->staging_dir_ = staging_root / stem;
  fs::create_directories(p->staging_dir_, ec);
  if (ec) return Status::IoError("cannot create " + p->staging_dir_.string() + ": " + ec.message());
  *out = std::move(p);
  return Status::Ok();
}

ProcessInstance::~ProcessInstance() {
  std::error_code ec;
  if (!staging_dir_.empty()) fs::remove_all(staging_dir_, ec);
  if (lock_fd_ >= 0) {
    ::unlink(lock_path_.c_str());
    ::close(lock_fd_);
  }
}

int ProcessInstance::ReapDead(const std::function<Status(const std::string& id)>& take_back) {
  int handled = 0;
  std::error_code ec;
  const auto day_ago = fs::file_time_type::clock::now() - std::chrono::hours(24);
  for (const auto& entry : fs::directory_iterator(root_, ec)) {
    const fs::path path = entry.path();
    const std::string name = path.filename().string();
    if (path.extension() != ".lock") {
      // Staging files of versions before per-process staging (upload-XXXXXX at the root).
      std::error_code e2;
      const bool old_staging = name.rfind("upload-", 0) == 0;
      const bool torn_lock = name.size() > 9 && name.compare(name.size() - 9, 9, ".lock.tmp") == 0;
      if ((old_staging || torn_lock) && entry.is_regular_file(e2) &&
          entry.last_write_time(e2) < day_ago) {
        fs::remove(path, e2);
      }
      continue;
    }
    if (path == lock_path_) continue;
    const std::string stem = path.stem().string();  // host_pid_start
    const size_t a = stem.find('_');
    const size_t b = stem.find('_', a == std::string::npos ? a : a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    if (stem.substr(0, a) != host_) continue;  // another host's process: not ours to judge
    const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
    if (fd < 0) continue;
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {  // held: that process is alive
      ::close(fd);
      continue;
    }
    const std::string id =
        stem.substr(0, a) + ":" + stem.substr(a + 1, b - a - 1) + ":" + stem.substr(b + 1);
    if (take_back(id).ok()) {
      std::error_code e2;
      fs::remove_all(root_ / stem, e2);
      ::unlink(path.c_str());  // still locked by us: nobody else reaps it meanwhile
      ++handled;
    }
    ::close(fd);
  }
  return handled;
}

}  // namespace calibd::server
