// Exports of an imu result (server/imu_method.h): CSV, the C header (ImuHeader also writes
// the per-IMU intrinsics of a full array result); the YAML is server/openvins_yaml.cc.
#include <Eigen/Dense>
#include <sstream>
#include <string>

#include "server/export_util.h"
#include "server/imu_method.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kImuModel =
    " * Model (imu, the imu_tk convention): a = T_a K_a (y_a - b_a),\n"
    " * omega = T_g K_g (y_g - b_g); y raw readings, b biases (reading units), K diagonal\n"
    " * scales (SI per reading unit), T_a upper triangular (the body frame is the\n"
    " * accelerometer's), T_g the gyroscope's misalignment to it. MATRIX = T K, applied by\n"
    " * *_imu_apply().\n";

}  // namespace

// imu (and any result with parameters.imus): per IMU a = MATRIX (y - BIAS) for both triads.
// `sub` prefixes the names that the array header has too (NAMES, and IMUS for symmetry).
Status ImuHeader(const json& params, const json& unc, const std::string& sub, HeaderWriter* w) {
  const json& imus = JsonAt(params, "imus");
  if (!imus.is_array() || imus.empty()) {
    return Status::Internal("stored result has no parameters.imus");
  }
  const size_t n = imus.size();
  std::vector<std::string> names;
  struct Triad {
    std::vector<std::vector<double>> bias, matrix;
  } triads[2];
  const char* sensors[2] = {"accelerometer", "gyroscope"};
  for (size_t i = 0; i < n; ++i) {
    names.push_back(JsonAt(imus[i], "name").is_string() ? imus[i]["name"].get<std::string>() : "");
    for (int t = 0; t < 2; ++t) {
      const json& p = JsonAt(imus[i], sensors[t]);
      std::vector<double> b, row;
      std::vector<std::vector<double>> m;
      bool ok = Numbers(JsonAt(p, "bias"), 3, &b) && JsonAt(p, "matrix").is_array() &&
                p["matrix"].size() == 3;
      for (size_t r = 0; ok && r < 3; ++r) {
        ok = Numbers(p["matrix"][r], 3, &row);
        m.push_back(row);
      }
      if (!ok) {
        return Status::NotDeterminable("the " + std::string(sensors[t]) + " of IMU '" +
                                       names.back() +
                                       "' has undefined parameters: no C header can be written");
      }
      triads[t].bias.push_back(b);
      for (auto& r : m) triads[t].matrix.push_back(r);
    }
  }
  w->Define(sub + "IMUS", std::to_string(n), "IMUs in the log");
  w->Names(sub + "NAMES", names);
  const char* units[2] = {"m/s^2", "rad/s"};
  for (int t = 0; t < 2; ++t) {
    const std::string upper = t == 0 ? "ACCEL_" : "GYRO_";
    w->Array2(upper + "BIAS", triads[t].bias, 3,
              std::string(sensors[t]) + " bias b per IMU, reading units");
    w->out() << "/* " << sensors[t] << " T K per IMU (3 rows each): " << units[t]
             << " per reading unit */\n"
             << "static const double " << w->macro() << upper << "MATRIX[" << n << "][3][3] = {\n";
    for (size_t i = 0; i < n; ++i) {
      w->out() << "    {";
      for (size_t r = 0; r < 3; ++r) {
        w->out() << (r ? ", " : "") << "{";
        for (size_t c = 0; c < 3; ++c) {
          w->out() << (c ? ", " : "") << CDouble(triads[t].matrix[3 * i + r][c]);
        }
        w->out() << "}";
      }
      w->out() << "},\n";
    }
    w->out() << "};\n";
  }
  // 1σ of the biases and scales per IMU, when every one is defined.
  const json& uimus = JsonAt(unc, "imus");
  for (int t = 0; t < 2; ++t) {
    for (const char* key : {"bias_std", "scale_std"}) {
      std::vector<std::vector<double>> rows;
      bool all = uimus.is_array() && uimus.size() == n;
      for (size_t i = 0; all && i < n; ++i) {
        std::vector<double> v;
        all = Numbers(JsonAt(JsonAt(uimus[i], sensors[t]), key), 3, &v);
        rows.push_back(v);
      }
      const std::string name =
          std::string(t == 0 ? "ACCEL_" : "GYRO_") + (key[0] == 'b' ? "BIAS_STD" : "SCALE_STD");
      if (all) {
        w->Array2(name, rows, 3, std::string("1 sigma of the ") + sensors[t] + " " + key);
      } else {
        w->out() << "/* " << w->macro() << name
                 << " is not written: some sigma are undefined (see format=json). */\n";
      }
    }
  }
  const std::string& M = w->macro();
  w->out()
      << "\n/* Calibrated acceleration (m/s^2) and angular rate (rad/s) of IMU `imu` from one\n"
         " * raw reading of its triads: a = ACCEL_MATRIX (y_a - ACCEL_BIAS),\n"
         " * omega = GYRO_MATRIX (y_g - GYRO_BIAS). Returns 0, or -1 (outputs untouched)\n"
         " * when imu is not an index below IMUS. */\n"
      << "static inline int " << w->func()
      << "apply(int imu, const double y_a[3], const double y_g[3], double a[3],\n"
      << "    double omega[3]) {\n"
      << "  int r, c;\n"
      << "  if (imu < 0 || imu >= " << M << sub << "IMUS) return -1;\n"
      << "  for (r = 0; r < 3; ++r) {\n"
      << "    a[r] = 0.0;\n"
      << "    omega[r] = 0.0;\n"
      << "    for (c = 0; c < 3; ++c) {\n"
      << "      a[r] += " << M << "ACCEL_MATRIX[imu][r][c] * (y_a[c] - " << M
      << "ACCEL_BIAS[imu][c]);\n"
      << "      omega[r] += " << M << "GYRO_MATRIX[imu][r][c] * (y_g[c] - " << M
      << "GYRO_BIAS[imu][c]);\n"
      << "    }\n"
      << "  }\n"
      << "  return 0;\n"
      << "}\n";
  return Status::Ok();
}

Status ImuResultToCsv(const json& result, std::string* out) {
  std::ostringstream csv;
  const json& params = JsonAt(result, "parameters");
  const json& unc = JsonAt(result, "uncertainty");
  const json& imus = JsonAt(params, "imus");
  if (!imus.is_array()) return Status::Internal("stored imu result has no parameters.imus");
  const json& uimus = JsonAt(unc, "imus");
  // One row per triad: value = matrix (reading - bias).
  csv << "imu,sensor,bias_x,bias_y,bias_z,scale_x,scale_y,scale_z";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) csv << ",matrix_" << r << c;
  csv << ",bias_std_x,bias_std_y,bias_std_z,scale_std_x,scale_std_y,scale_std_z";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) csv << ",misalignment_std_" << r << c;
  csv << "\n";
  for (size_t i = 0; i < imus.size(); ++i) {
    const json& u = uimus.is_array() && i < uimus.size() ? uimus[i] : json();
    const json& name = JsonAt(imus[i], "name");
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json& p = JsonAt(imus[i], sensor);
      const json& ps = JsonAt(u, sensor);
      csv << CsvField(name.is_string() ? name.get<std::string>() : "") << "," << sensor;
      auto vec = [&](const json& v) {
        for (size_t k = 0; k < 3; ++k)
          csv << "," << (v.is_array() && k < v.size() ? CsvNumber(v[k]) : "");
      };
      auto mat = [&](const json& m) {
        for (size_t r = 0; r < 3; ++r) vec(m.is_array() && r < m.size() ? m[r] : json());
      };
      vec(JsonAt(p, "bias"));
      vec(JsonAt(p, "scale"));
      mat(JsonAt(p, "matrix"));
      vec(JsonAt(ps, "bias_std"));
      vec(JsonAt(ps, "scale_std"));
      mat(JsonAt(ps, "misalignment_std"));
      csv << "\n";
    }
  }
  *out = csv.str();
  return Status::Ok();
}

Status ImuResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return WriteCHeader(
      result, context, "imu", kImuModel,
      [&](const json& params, const json& unc, HeaderWriter* w) {
        return ImuHeader(params, unc, "", w);
      },
      out);
}

}  // namespace calibd::server
