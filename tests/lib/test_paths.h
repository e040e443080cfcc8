// Where a test finds the calibd it runs and the source tree it reads (README, scripts, corpus
// files). Found at run time, not passed as compile definitions: a compile command that holds no
// absolute path is the same in every checkout, so a clean checkout elsewhere on the machine (CI's)
// reuses the compiler cache (scripts/ccache.sh) instead of recompiling every test file.
//   calibd:      $CALIBD_BINARY if set, else <build>/calibd (tests/CMakeLists.txt puts the test
//                executables in <build>/tests/ and calibd in <build>/).
//   source tree: $CALIBD_SOURCE_DIR if set, else the path CMake wrote to
//                <build>/tests/calibd_source_dir at configure time.
// A path that cannot be found aborts the test program with a message naming what is missing.
#ifndef CALIBD_TESTS_LIB_TEST_PATHS_H_
#define CALIBD_TESTS_LIB_TEST_PATHS_H_

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace calibd::test_paths {

// The directory holding the running test executable (/proc/self/exe).
inline std::filesystem::path ExecutableDir() {
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) {
    std::fprintf(stderr, "test_paths: cannot read /proc/self/exe: %s\n", ec.message().c_str());
    std::abort();
  }
  return exe.parent_path();
}

// The built calibd. Computed once; call it before fork() in code that runs calibd in a child.
inline const std::string& CalibdBinary() {
  static const std::string path = [] {
    if (const char* env = std::getenv("CALIBD_BINARY"); env != nullptr && *env != '\0')
      return std::string(env);
    const auto candidate = ExecutableDir().parent_path() / "calibd";
    if (!std::filesystem::exists(candidate)) {
      std::fprintf(stderr, "test_paths: no calibd at %s (set CALIBD_BINARY)\n", candidate.c_str());
      std::abort();
    }
    return candidate.string();
  }();
  return path;
}

// The source tree, without a trailing slash.
inline const std::string& SourceDir() {
  static const std::string path = [] {
    if (const char* env = std::getenv("CALIBD_SOURCE_DIR"); env != nullptr && *env != '\0')
      return std::string(env);
    const auto file = ExecutableDir() / "calibd_source_dir";
    std::ifstream in(file);
    std::string line;
    if (!in || !std::getline(in, line) || line.empty()) {
      std::fprintf(stderr, "test_paths: cannot read %s (set CALIBD_SOURCE_DIR)\n", file.c_str());
      std::abort();
    }
    return line;
  }();
  return path;
}

// A file the build put beside the test executables (a shared library such as the clock-skew shim).
inline std::string BesideTests(const std::string& name) {
  return (ExecutableDir() / name).string();
}

}  // namespace calibd::test_paths

#endif  // CALIBD_TESTS_LIB_TEST_PATHS_H_
