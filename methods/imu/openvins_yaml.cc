#include "methods/imu/openvins_yaml.h"

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "methods/acceptance.h"
#include "methods/export_util.h"
#include "methods/imu/imu_result.h"

namespace calibd::server {

using nlohmann::json;

namespace {

std::string Num(double v) { return CDouble(v); }  // a real for cv::FileStorage; no -0.0

// M = Q L with Q a rotation and L lower triangular with a positive diagonal (QL decomposition,
// from the QR decomposition of M J, J the exchange matrix: M J = Q1 U, Q = Q1 J, L = J U J).
// False when M is singular or mirrors (det <= 0: no rotation Q exists).
bool QlDecomposition(const Eigen::Matrix3d& m, Eigen::Matrix3d* q, Eigen::Matrix3d* l) {
  if (!(m.determinant() > 0) || !m.allFinite()) return false;
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  j(0, 2) = j(1, 1) = j(2, 0) = 1;
  Eigen::HouseholderQR<Eigen::Matrix3d> qr(m * j);
  Eigen::Matrix3d q1 = qr.householderQ();
  Eigen::Matrix3d u = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int i = 0; i < 3; ++i) {
    if (u(i, i) < 0) {
      u.row(i) *= -1;
      q1.col(i) *= -1;
    }
  }
  *q = q1 * j;
  *l = j * u * j;
  return q->determinant() > 0;
}

void WriteMatrix(std::ostringstream& y, const char* key, const Eigen::Matrix3d& m) {
  y << "  " << key << ":\n";
  for (int r = 0; r < 3; ++r) {
    y << "    - [" << Num(m(r, 0)) << ", " << Num(m(r, 1)) << ", " << Num(m(r, 2)) << "]\n";
  }
}

}  // namespace

Status ImuResultToOpenVinsYaml(const json& result, const ExportContext& context, std::string* out) {
  results::ImuResult typed;
  if (Status s = results::FromJson(result, &typed); !s.ok()) {
    return UnreadableStoredResult(s);
  }
  if (!typed.parameters || typed.parameters->imus.empty()) {
    return Status::Internal("stored imu result has no imus");
  }
  const results::ImuParameters& params = *typed.parameters;
  const results::ImuDiagnostics& diagnostics = typed.diagnostics;
  if (!params.accel_unit || !std::isfinite(*params.accel_unit) || !params.gyro_unit ||
      !std::isfinite(*params.gyro_unit) || !diagnostics.rate || !std::isfinite(*diagnostics.rate)) {
    return Status::NotDeterminable(
        "this imu result predates the reading units and rate being stored with it; run the job "
        "again (POST /api/v1/jobs with its recording) to export it for OpenVINS");
  }
  const double accel_unit = *params.accel_unit;
  const double gyro_unit = *params.gyro_unit;
  const double rate = *diagnostics.rate;
  const std::vector<results::ImuTriads>& imus = params.imus;
  double nominal_accel_bias = 0, nominal_gyro_bias = 0;
  if (context.config.is_object()) {
    for (auto [key, value] : {std::pair{"nominal_accel_bias", &nominal_accel_bias},
                              std::pair{"nominal_gyro_bias", &nominal_gyro_bias}}) {
      if (!context.config.contains(key) || context.config[key].is_null()) continue;
      const std::optional<double> n = Number(context.config[key]);
      if (!n || !std::isfinite(*n)) {
        return Status::Internal(std::string("the job's config key '") + key +
                                "' is not a number: " + context.config[key].dump().substr(0, 60));
      }
      *value = *n;
    }
  }

  std::ostringstream y;
  y << "%YAML:1.0\n"
    << "# OpenVINS kalibr_imu_chain.yaml: IMU intrinsics from calibd imu job " << context.job_id
    << " of device '" << CommentSafe(context.device) << "', finished "
    << CommentSafe(context.finished_at) << ".\n"
    << "# OpenVINS model (calibrated = kalibr): a_I = Da (a_m - b_a), w_I = R_IMUtoGYRO^T Dw\n"
    << "# (w_m - b_g), Da = Ta^-1 and Dw = Tw^-1 lower triangular, readings a_m, w_m in SI.\n"
    << "# calibd's a = T_a K_a (y_a - b_a), w = T_g K_g (y_g - b_g) are the same up to the\n"
    << "# rotation R_BODYtoI below (frame I: Da lower triangular; calibd's body frame: T_a\n"
    << "# upper triangular). Noise figures: from the noise job the calibration named in\n"
    << "# accel_noise/gyro_noise ({\"job\": ID}); else the noise densities from the static\n"
    << "# intervals' per-sample spread / sqrt(update_rate), and no random walks (a hand-held log\n"
    << "# cannot show them: run a calibd noise job on a long stationary log).\n";
  for (size_t k = 0; k < imus.size(); ++k) {
    const results::ImuTriads& imu = imus[k];
    Eigen::Matrix3d ma = imu.accelerometer.matrix, mg = imu.gyroscope.matrix;
    const Eigen::Vector3d ba = imu.accelerometer.bias, bg = imu.gyroscope.bias;
    if (!ma.allFinite() || !mg.allFinite() || !ba.allFinite() || !bg.allFinite()) {
      return Status::Internal("stored imu result lacks a matrix or bias");
    }
    const std::string& name = imu.name;
    ma /= accel_unit;  // per SI reading
    mg /= gyro_unit;
    Eigen::Matrix3d r, la, q, lg;
    if (!QlDecomposition(ma, &r, &la)) {
      return Status::NotDeterminable("IMU " + name +
                                     ": the accelerometer matrix is singular or mirrors the axes; "
                                     "it has no OpenVINS form");
    }
    if (!QlDecomposition(r.transpose() * mg, &q, &lg)) {
      return Status::NotDeterminable("IMU " + name +
                                     ": the gyroscope matrix is singular or mirrors the axes; it "
                                     "has no OpenVINS form");
    }
    double accel_sigma = 0, gyro_sigma = 0;
    if (k < diagnostics.imus.size()) {
      const results::ImuFitDiagnostics& d = diagnostics.imus[k];
      if (d.accel_noise.allFinite()) accel_sigma = d.accel_noise.maxCoeff();
      if (d.gyro_noise.allFinite()) gyro_sigma = d.gyro_noise.maxCoeff();
    }
    // a = M_a (y - b) = (M_a / u) (u (y - n) - u (b - n)): a driver publishing u (y - n), n the
    // nominal offset of offset-binary counts, leaves the bias u (b - n) in SI.
    const Eigen::Vector3d ba_si = (ba.array() - nominal_accel_bias).matrix() * accel_unit;
    const Eigen::Vector3d bg_si = (bg.array() - nominal_gyro_bias).matrix() * gyro_unit;
    y << "imu" << k << ":  # calibd IMU " << CommentSafe(name) << "\n"
      << "  T_i_b:\n"
      << "    - [1.0, 0.0, 0.0, 0.0]\n"
      << "    - [0.0, 1.0, 0.0, 0.0]\n"
      << "    - [0.0, 0.0, 1.0, 0.0]\n"
      << "    - [0.0, 0.0, 0.0, 1.0]\n";
    // Kalibr's noise figures: from the noise job the calibration used (accel_noise/gyro_noise
    // {"job": ID}), else the densities from the statics' spread; random walks only from a job.
    for (int type = 0; type < 2; ++type) {
      const char* sensor = type == 0 ? "accelerometer" : "gyroscope";
      const char* units[2][2] = {{"m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)"},
                                 {"rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)"}};
      const std::optional<results::ImuNoiseModel>* from_job =
          diagnostics.noise_model ? (type == 0 ? &diagnostics.noise_model->accelerometer
                                               : &diagnostics.noise_model->gyroscope)
                                  : nullptr;
      const results::ImuNoiseModel* model =
          from_job != nullptr && from_job->has_value() && (*from_job)->job ? &**from_job : nullptr;
      const std::string job = model != nullptr ? std::to_string(*model->job) : "";
      const double sigma = type == 0 ? accel_sigma : gyro_sigma;
      if (model != nullptr && std::isfinite(model->white_noise)) {
        y << "  " << sensor << "_noise_density: " << Num(model->white_noise) << "  # "
          << units[type][0] << ", largest axis, calibd noise job " << job << "\n";
      } else if (sigma > 0 && rate > 0) {
        y << "  " << sensor << "_noise_density: " << Num(sigma / std::sqrt(rate)) << "  # "
          << units[type][0] << ", largest axis, from the static intervals\n";
      }
      if (model != nullptr && std::isfinite(model->random_walk)) {
        y << "  " << sensor << "_random_walk: " << Num(model->random_walk) << "  # "
          << units[type][1] << ", largest axis, calibd noise job " << job << "\n";
      } else {
        y << "  # " << sensor << "_random_walk: not known; run a calibd noise job and give it as "
          << (type == 0 ? "accel_noise" : "gyro_noise") << ": {\"job\": ID}\n";
      }
    }
    y << "  rostopic: /imu" << k << "\n"
      << "  time_offset: 0.0\n"
      << "  update_rate: " << MeasuredRate(rate) << "\n"
      << "  model: \"calibrated\"\n";
    WriteMatrix(y, "Tw", lg.inverse());
    WriteMatrix(y, "R_IMUtoGYRO", q.transpose());
    WriteMatrix(y, "Ta", la.inverse());
    WriteMatrix(y, "R_IMUtoACC", Eigen::Matrix3d::Identity());
    WriteMatrix(y, "Tg", Eigen::Matrix3d::Zero());
    y << "  # R_BODYtoI (calibd body frame to I, rows):";
    for (int i = 0; i < 3; ++i) {
      y << " [" << Num(r(0, i)) << ", " << Num(r(1, i)) << ", " << Num(r(2, i)) << "]";
    }
    y << "\n  # biases in SI for initialising the filter (readings u (y - n), n the nominal offset "
      << Num(nominal_accel_bias) << " / " << Num(nominal_gyro_bias) << " counts):\n"
      << "  # b_a = [" << Num(ba_si(0)) << ", " << Num(ba_si(1)) << ", " << Num(ba_si(2))
      << "] m/s^2, b_g = [" << Num(bg_si(0)) << ", " << Num(bg_si(1)) << ", " << Num(bg_si(2))
      << "] rad/s\n";
  }
  *out = y.str();
  return Status::Ok();
}

}  // namespace calibd::server
