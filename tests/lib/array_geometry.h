// An array's nominal positions (3 × K, metres) as the config's `geometry.positions` JSON:
// [[x, y, z], ...], for tests and benchmarks that write array configs.
#ifndef CALIBD_TESTS_LIB_ARRAY_GEOMETRY_H_
#define CALIBD_TESTS_LIB_ARRAY_GEOMETRY_H_

#include <Eigen/Core>
#include <nlohmann/json.hpp>

namespace calibd::testing {

inline nlohmann::json GeometryPositions(const Eigen::Matrix3Xd& p) {
  nlohmann::json positions = nlohmann::json::array();
  for (Eigen::Index k = 0; k < p.cols(); ++k) positions.push_back({p(0, k), p(1, k), p(2, k)});
  return positions;
}

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_ARRAY_GEOMETRY_H_
