// Exports of an imu result (methods/imu/imu_method.h): CSV, the C header (ImuHeader also writes
// the per-IMU intrinsics of a full array result); the YAML is methods/imu/openvins_yaml.cc. Each
// reads the stored result once into results::ImuResult; one that does not read is kInternal with
// the reader's message.
#include <Eigen/Dense>
#include <sstream>
#include <string>
#include <utility>

#include "methods/export_util.h"
#include "methods/imu/imu_method.h"
#include "methods/imu/imu_result.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kImuModel =
    " * Model (imu, the imu_tk convention): a = T_a K_a (y_a - b_a),\n"
    " * omega = T_g K_g (y_g - b_g); y raw readings, b biases (reading units), K diagonal\n"
    " * scales (SI per reading unit), T_a upper triangular (the body frame is the\n"
    " * accelerometer's), T_g the gyroscope's misalignment to it. MATRIX = T K, applied by\n"
    " * *_imu_apply().\n";

// A stored imu result, typed; kInternal naming the first problem when it does not read.
Status ReadResult(const json& result, results::ImuResult* out) {
  Status s = results::FromJson(result, out);
  if (!s.ok()) return UnreadableStoredResult(s);
  if (!out->parameters) {
    return Status::Internal("stored imu result is the partial diagnostics of a failed run");
  }
  return Status::Ok();
}

}  // namespace

// The per-IMU part of another method's result (array full): reads what the header needs of
// parameters.imus[] (name, bias, matrix) and uncertainty.imus[] (bias_std, scale_std).
Status ImuHeader(const json& params, const json& unc, const std::string& sub, HeaderWriter* w) {
  std::vector<results::ImuTriads> imus;
  std::vector<results::ImuTriadsStd> stds;
  results::JsonReader p(params, "stored result's parameters");
  p.ReadArray("imus", &imus, [](const results::JsonReader& e, results::ImuTriads* t) {
    e.Read("name", &t->name);
    for (auto [key, triad] :
         {std::pair<const char*, results::SensorTriad*>{"accelerometer", &t->accelerometer},
          {"gyroscope", &t->gyroscope}}) {
      const results::JsonReader r = e.Object(key);
      r.Read("bias", &triad->bias);
      r.Read("matrix", &triad->matrix);
    }
  });
  if (!p.ok()) return Status::Internal(p.status().message());
  // Uncertainties that do not read are left out of the header (as undefined ones are).
  results::JsonReader u(unc, "stored result's uncertainty");
  u.ReadArray("imus", &stds, [](const results::JsonReader& e, results::ImuTriadsStd* t) {
    for (auto [key, triad] :
         {std::pair<const char*, results::SensorTriadStd*>{"accelerometer", &t->accelerometer},
          {"gyroscope", &t->gyroscope}}) {
      const results::JsonReader r = e.Object(key);
      r.Read("bias_std", &triad->bias_std);
      r.Read("scale_std", &triad->scale_std);
    }
  });
  if (!u.ok()) stds.clear();
  return ImuHeader(imus, stds, sub, w);
}

// imu (and any result with per-IMU triads): per IMU a = MATRIX (y - BIAS) for both triads.
// `sub` prefixes the names that the array header has too (NAMES, and IMUS for symmetry).
Status ImuHeader(const std::vector<results::ImuTriads>& imus,
                 const std::vector<results::ImuTriadsStd>& stds, const std::string& sub,
                 HeaderWriter* w) {
  if (imus.empty()) return Status::Internal("stored result has no parameters.imus");
  const size_t n = imus.size();
  std::vector<std::string> names;
  struct Triad {
    std::vector<std::vector<double>> bias, matrix;
  } triads[2];
  const char* sensors[2] = {"accelerometer", "gyroscope"};
  for (size_t i = 0; i < n; ++i) {
    names.push_back(imus[i].name);
    for (int t = 0; t < 2; ++t) {
      const results::SensorTriad& p = t == 0 ? imus[i].accelerometer : imus[i].gyroscope;
      if (!p.bias.allFinite() || !p.matrix.allFinite()) {
        return Status::NotDeterminable("the " + std::string(sensors[t]) + " of IMU '" +
                                       names.back() +
                                       "' has undefined parameters: no C header can be written");
      }
      triads[t].bias.push_back({p.bias(0), p.bias(1), p.bias(2)});
      for (int r = 0; r < 3; ++r) {
        triads[t].matrix.push_back({p.matrix(r, 0), p.matrix(r, 1), p.matrix(r, 2)});
      }
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
  for (int t = 0; t < 2; ++t) {
    for (const char* key : {"bias_std", "scale_std"}) {
      std::vector<std::vector<double>> rows;
      bool all = stds.size() == n;
      for (size_t i = 0; all && i < n; ++i) {
        const results::SensorTriadStd& sd = t == 0 ? stds[i].accelerometer : stds[i].gyroscope;
        const Eigen::Vector3d& v = key[0] == 'b' ? sd.bias_std : sd.scale_std;
        all = v.allFinite();
        rows.push_back({v(0), v(1), v(2)});
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
  results::ImuResult r;
  Status s = ReadResult(result, &r);
  if (!s.ok()) return s;
  std::ostringstream csv;
  // One row per triad: value = matrix (reading - bias).
  csv << "imu,sensor,bias_x,bias_y,bias_z,scale_x,scale_y,scale_z";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) csv << ",matrix_" << r << c;
  csv << ",bias_std_x,bias_std_y,bias_std_z,scale_std_x,scale_std_y,scale_std_z";
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) csv << ",misalignment_std_" << r << c;
  csv << "\n";
  // An undefined value (null in JSON) is an empty cell, never 0.
  auto vec = [&](const Eigen::Vector3d& v) {
    for (int k = 0; k < 3; ++k) csv << "," << CsvNumber(results::Num(v(k)));
  };
  auto mat = [&](const Eigen::Matrix3d& m) {
    for (int row = 0; row < 3; ++row) vec(m.row(row).transpose());
  };
  const std::vector<results::ImuTriads>& imus = r.parameters->imus;
  for (size_t i = 0; i < imus.size(); ++i) {
    const results::ImuTriadsStd& u = r.uncertainty->imus[i];
    for (int t = 0; t < 2; ++t) {
      const results::SensorTriad& p = t == 0 ? imus[i].accelerometer : imus[i].gyroscope;
      const results::SensorTriadStd& ps = t == 0 ? u.accelerometer : u.gyroscope;
      csv << CsvField(imus[i].name) << "," << (t == 0 ? "accelerometer" : "gyroscope");
      vec(p.bias);
      vec(p.scale);
      mat(p.matrix);
      vec(ps.bias_std);
      vec(ps.scale_std);
      mat(ps.misalignment_std);
      csv << "\n";
    }
  }
  *out = csv.str();
  return Status::Ok();
}

Status ImuResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  results::ImuResult r;
  Status s = ReadResult(result, &r);
  if (!s.ok()) return s;
  return WriteCHeader(
      result, context, "imu", kImuModel,
      [&](const json&, const json&, HeaderWriter* w) {
        return ImuHeader(r.parameters->imus, r.uncertainty->imus, "", w);
      },
      out);
}

}  // namespace calibd::server
