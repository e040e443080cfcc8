// CK-Explorer's public accelerometer + magnetometer log (acc_mag_log.csv; where it comes from:
// tests/core/mag_data_test.cc) as calibd's CSV: a time column at its 100 Hz, then a0 (g) and m0
// (gauss). Tests that need it skip when it is absent.
#ifndef CALIBD_TESTS_LIB_MAG_PUBLIC_LOG_H_
#define CALIBD_TESTS_LIB_MAG_PUBLIC_LOG_H_

#include <cstdlib>
#include <fstream>
#include <optional>
#include <string>

namespace calibd::testing {

// The log as CSV text, or nullopt when $CALIBD_MAG_DATA (default /work/data/mag) lacks it.
inline std::optional<std::string> CkExplorerAccMagCsv() {
  const char* dir = std::getenv("CALIBD_MAG_DATA");
  std::ifstream in(std::string(dir ? dir : "/work/data/mag") + "/acc_mag_log.csv");
  if (!in) return std::nullopt;
  std::string line, csv = "t,a0_x,a0_y,a0_z,m0_x,m0_y,m0_z\n";
  std::getline(in, line);  // the file's own header
  for (int i = 0; std::getline(in, line); ++i) {
    if (!line.empty()) csv += std::to_string(i * 0.01) + "," + line + "\n";
  }
  return csv;
}

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_MAG_PUBLIC_LOG_H_
