// Read-only files in tests that run as root (CI does): root ignores file permissions, so a file
// is read-only only to another user. As root, these helpers run the code or the process under
// test as nobody (uid and gid 65534, no supplementary groups); as any other user they run it as
// that user, where the permissions already hold. Either may be unavailable (root without
// setpriv, or a temporary folder nobody cannot reach): the caller then skips, saying why.
#ifndef CALIBD_TESTS_LIB_UNPRIVILEGED_H_
#define CALIBD_TESTS_LIB_UNPRIVILEGED_H_

#include <grp.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>

namespace calibd::unprivileged {

constexpr uid_t kNobody = 65534;
// The exit code of a child that could not become nobody or reach the files (not a failure).
constexpr int kUnprivilegedUnavailable = 77;

inline bool RunningAsRoot() { return ::geteuid() == 0; }

// Makes `dir` (a test's temporary folder) searchable and readable by everyone, so nobody can
// open the files in it (their own modes still apply). mkdtemp makes it 0700.
inline bool OpenFolderToNobody(const std::string& dir) { return ::chmod(dir.c_str(), 0755) == 0; }

// The command prefix that runs a program as nobody when root ("setpriv ... "), "" when not root.
// False (with *why) when root cannot: no setpriv (util-linux), or nobody cannot read
// `readable` (a folder above it is closed to others).
inline bool UnprivilegedCommand(const std::string& readable, std::string* prefix,
                                std::string* why) {
  prefix->clear();
  if (!RunningAsRoot()) return true;
  const std::string setpriv = "setpriv --reuid=65534 --regid=65534 --clear-groups ";
  if (std::system((setpriv + "true >/dev/null 2>&1").c_str()) != 0) {
    *why = "running as root and setpriv (util-linux) cannot run a program as nobody";
    return false;
  }
  if (std::system((setpriv + "test -r '" + readable + "'").c_str()) != 0) {
    *why = "running as root and nobody cannot read " + readable;
    return false;
  }
  *prefix = setpriv;
  return true;
}

// Runs `body` (gtest assertions allowed) as nobody in a forked child when root, else in this
// process. Returns 0 when it ran without a failure, kUnprivilegedUnavailable when the child could
// not become nobody or read `readable`, else 1 (the child printed its failures). Fork only where
// no other thread of the test runs.
inline int RunUnprivileged(const std::string& readable, const std::function<void()>& body) {
  if (!RunningAsRoot()) {
    body();
    return ::testing::Test::HasFailure() ? 1 : 0;
  }
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid < 0) return kUnprivilegedUnavailable;
  if (pid == 0) {
    if (::setgroups(0, nullptr) != 0 || ::setresgid(kNobody, kNobody, kNobody) != 0 ||
        ::setresuid(kNobody, kNobody, kNobody) != 0 || ::access(readable.c_str(), R_OK) != 0) {
      ::_exit(kUnprivilegedUnavailable);
    }
    body();
    const bool failed = ::testing::Test::HasFailure();
    std::fflush(stdout);
    std::fflush(stderr);
    ::_exit(failed ? 1 : 0);  // no atexit handlers: the parent owns the test's state
  }
  int status = 0;
  if (::waitpid(pid, &status, 0) != pid) return 1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 1;
}

}  // namespace calibd::unprivileged

#endif  // CALIBD_TESTS_LIB_UNPRIVILEGED_H_
