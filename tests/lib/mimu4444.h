// The public MIMU4444 recordings (exp_N/data.bin; source and packet format in
// tests/core/array_full_mimu4444_test.cc) read into a recording, for the server tests that use
// them ($CALIBD_MIMU4444_DATA, default /work/data/mimu4444; the tests skip when absent).
#ifndef CALIBD_TESTS_LIB_MIMU4444_H_
#define CALIBD_TESTS_LIB_MIMU4444_H_

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "core/array_simulation.h"
#include "formats/recording.h"

namespace calibd::server::testing {

inline std::string Mimu4444Dir() {
  const char* env = std::getenv("CALIBD_MIMU4444_DATA");
  return env && *env ? env : "/work/data/mimu4444";
}

// One data.bin as a recording (m/s², deg/s, board frame; packet format in the core test).
inline bool ReadMimu4444(const std::string& path, ArrayRecording* rec) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  const std::string d((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  constexpr size_t kPacket = 106;
  auto u8 = [&](size_t i) { return static_cast<unsigned>(static_cast<unsigned char>(d[i])); };
  auto i16 = [&](size_t i) { return static_cast<int16_t>((u8(i) << 8) | u8(i + 1)); };
  std::vector<std::array<int16_t, 48>> rows;
  std::vector<double> t;
  uint32_t last_ts = 0;
  double time = 0;
  for (size_t i = 0; i + kPacket <= d.size();) {
    unsigned sum = 0;
    if (u8(i) == 0xAA)
      for (size_t j = 0; j < kPacket - 2; ++j) sum += u8(i + j);
    if (u8(i) != 0xAA || (sum & 0xFFFF) != ((u8(i + 104) << 8) | u8(i + 105))) {
      ++i;
      continue;
    }
    const uint32_t ts = (u8(i + 4) << 24) | (u8(i + 5) << 16) | (u8(i + 6) << 8) | u8(i + 7);
    if (!rows.empty()) time += static_cast<uint32_t>(ts - last_ts) / 64e6;
    last_ts = ts;
    std::array<int16_t, 48> row;
    for (int c = 0; c < 48; ++c) row[c] = i16(i + 8 + 2 * c);
    rows.push_back(row);
    t.push_back(time);
    i += kPacket;
  }
  const Eigen::Index n = static_cast<Eigen::Index>(rows.size());
  rec->t = Eigen::Map<Eigen::VectorXd>(t.data(), n);
  rec->accel.resize(n, 24);
  rec->gyro.resize(n, 24);
  const double a_unit = core::kStandardGravity / 2048, g_unit = 1 / 16.4;
  for (Eigen::Index r = 0; r < n; ++r)
    for (int k = 0; k < 8; ++k) {
      Eigen::Vector3d a, g;
      for (int i = 0; i < 3; ++i) {
        a(i) = rows[r][6 * k + i] * a_unit;
        g(i) = rows[r][6 * k + 3 + i] * g_unit;
      }
      if (k % 2 == 1) {  // underside: x <-> -y, z -> -z
        a = Eigen::Vector3d(-a.y(), -a.x(), -a.z());
        g = Eigen::Vector3d(-g.y(), -g.x(), -g.z());
      }
      rec->accel.row(r).segment<3>(3 * k) = a.transpose();
      rec->gyro.row(r).segment<3>(3 * k) = g.transpose();
    }
  rec->accel_names.clear();
  rec->gyro_names.clear();
  for (int k = 0; k < 8; ++k) {
    rec->accel_names.push_back("a" + std::to_string(k));
    rec->gyro_names.push_back("g" + std::to_string(k));
  }
  return n > 0;
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_LIB_MIMU4444_H_
