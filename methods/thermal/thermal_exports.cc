// Exports of a thermal result (methods/thermal/thermal_method.h): csv, a C99 header, ArduPilot's
// INS_TCALn_* and PX4's TC_* parameter files.
#include <Eigen/QR>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "methods/export_util.h"
#include "methods/thermal/thermal_method.h"

namespace calibd::server {

namespace {

const char* const kSensors[2] = {"accelerometer", "gyroscope"};
const char kAxes[3] = {'x', 'y', 'z'};

std::vector<double> Coefficients(const json& imu, int s, int a) {
  return imu.at(kSensors[s])
      .at("bias")
      .at("coefficients")
      .at(static_cast<size_t>(a))
      .get<std::vector<double>>();
}

double Curve(const std::vector<double>& c, double x) {
  double v = 0, p = 1;
  for (double ck : c) {
    p *= x;
    v += ck * p;
  }
  return v;
}

std::string Num(double v, const char* fmt = "%.9g") {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

// Catches a stored result that lacks its keys (kInternal, as the other methods' exports).
template <typename F>
Status Guarded(F&& f) {
  try {
    return f();
  } catch (const std::exception& e) {
    return Status::Internal(std::string("the thermal result lacks its SPEC keys: ") + e.what());
  }
}

}  // namespace

FirmwareCubic RefitCubic(const std::vector<double>& coefficients, double t_ref, double t_min,
                         double t_max, double reference) {
  const int n = 201;
  Eigen::MatrixXd a(n, 4);
  Eigen::VectorXd y(n);
  for (int i = 0; i < n; ++i) {
    const double temp = t_min + (t_max - t_min) * i / (n - 1);
    const double d = temp - reference;
    a.row(i) << 1, d, d * d, d * d * d;
    y(i) = Curve(coefficients, temp - t_ref);
  }
  const Eigen::Vector4d p = a.colPivHouseholderQr().solve(y);
  FirmwareCubic out;
  out.constant = p(0);
  for (int k = 0; k < 3; ++k) out.a[k] = p(k + 1);
  out.max_error = (a * p - y).cwiseAbs().maxCoeff();
  return out;
}

Status ThermalResultToCsv(const json& result, std::string* out) {
  return Guarded([&] {
    std::ostringstream c;
    c << "imu,sensor,axis,t_ref,t_min,t_max,order,c1,c2,c3,c4,c5,c6,c7,c8,max_band_std\n";
    const json& unc = result.at("uncertainty").at("imus");
    const json& imus = result.at("parameters").at("imus");
    for (size_t i = 0; i < imus.size(); ++i) {
      const json& imu = imus[i];
      for (int s = 0; s < 2; ++s) {
        for (int a = 0; a < 3; ++a) {
          const std::vector<double> co = Coefficients(imu, s, a);
          c << CsvField(imu.at("name").get<std::string>()) << "," << kSensors[s] << "," << kAxes[a]
            << "," << CsvNumber(imu.at("t_ref")) << "," << CsvNumber(imu.at("t_min")) << ","
            << CsvNumber(imu.at("t_max")) << "," << co.size();
          for (size_t k = 0; k < 8; ++k) c << "," << (k < co.size() ? CsvNumber(co[k]) : "");
          double worst = 0;
          for (const json& v : unc[i].at(kSensors[s]).at("bias").at("std").at(a)) {
            worst = std::max(worst, v.get<double>());
          }
          c << "," << CsvNumber(worst) << "\n";
        }
      }
    }
    *out = c.str();
    return Status::Ok();
  });
}

Status ThermalResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return Guarded([&] {
    return WriteCHeader(
        result, context, "thermal",
        " * deviation(T) = sum_k c[k] (clamp(T, T_MIN, T_MAX) - T_REF)^(k+1), per axis, SI units;\n"
        " * corrected reading = reading - deviation(T) (sensor frame, before the room-temperature\n"
        " * calibration). The curve is held at its end value outside [T_MIN, T_MAX].",
        [&](const json& params, const json&, HeaderWriter* w) {
          for (const json& imu : params.at("imus")) {
            const std::string n = IdentifierStem(imu.at("name").get<std::string>());
            w->Define("IMU" + n + "_T_REF", CDouble(imu.at("t_ref").get<double>()), "degC");
            w->Define("IMU" + n + "_T_MIN", CDouble(imu.at("t_min").get<double>()), "degC");
            w->Define("IMU" + n + "_T_MAX", CDouble(imu.at("t_max").get<double>()), "degC");
            for (int s = 0; s < 2; ++s) {
              std::vector<std::vector<double>> rows;
              for (int a = 0; a < 3; ++a) {
                std::vector<double> co = Coefficients(imu, s, a);
                co.resize(8, 0.0);
                rows.push_back(co);
              }
              w->Array2("IMU" + n + "_" + (s ? "GYRO" : "ACCEL") + "_C", rows, 8,
                        std::string(s ? "rad/s" : "m/s^2") + " per degC^(k+1), x y z");
            }
            const std::string m = w->macro() + "IMU" + n;
            w->out()
                << "/* The deviation of the accelerometer (m/s^2) and gyroscope (rad/s) biases "
                   "from t_ref at temperature t (degC). */\n"
                << "static inline void " << w->func() << "imu" << n
                << "_deviation(double t, double accel[3], double gyro[3]) {\n"
                << "  int a, k;\n"
                << "  double x, p;\n"
                << "  if (t < " << m << "_T_MIN) t = " << m << "_T_MIN;\n"
                << "  if (t > " << m << "_T_MAX) t = " << m << "_T_MAX;\n"
                << "  x = t - " << m << "_T_REF;\n"
                << "  for (a = 0; a < 3; ++a) {\n"
                << "    accel[a] = 0;\n    gyro[a] = 0;\n    p = 1;\n"
                << "    for (k = 0; k < 8; ++k) {\n"
                << "      p *= x;\n"
                << "      accel[a] += " << m << "_ACCEL_C[a][k] * p;\n"
                << "      gyro[a] += " << m << "_GYRO_C[a][k] * p;\n"
                << "    }\n  }\n}\n";
          }
          return Status::Ok();
        },
        out);
  });
}

// ArduPilot: INS_TCALn_ACCk_X = a_k × 1e6 about 35 °C (AP_InertialSensor_tempcal.cpp: the
// firmware subtracts (c1 + (c2 + c3 d) d) d × 1e-6 at d = clamp(T) − 35 and adds it back at the
// temperature of the room calibration, so the constant term cancels and is not stored).
Status ThermalResultToArduPilot(const json& result, const ExportContext& context,
                                std::string* out) {
  return Guarded([&] {
    const json& imus = result.at("parameters").at("imus");
    if (imus.size() > 3) {
      return Status::NotDeterminable(
          "ArduPilot holds at most 3 IMUs (INS_TCAL1..3); the result "
          "has " +
          std::to_string(imus.size()));
    }
    std::ostringstream p;
    p << "# ArduPilot temperature calibration from calibd thermal job " << context.job_id
      << " of device '" << CommentSafe(context.device) << "', " << CommentSafe(context.finished_at)
      << ".\n# Order 3 about 35 degC, no constant term, x1e6, sensor frame. Scale curves are "
         "not held by ArduPilot: left out.\n";
    for (size_t i = 0; i < imus.size(); ++i) {
      const json& imu = imus[i];
      const double t_ref = imu.at("t_ref").get<double>(), lo = imu.at("t_min").get<double>(),
                   hi = imu.at("t_max").get<double>();
      const std::string n = std::to_string(i + 1);
      FirmwareCubic fit[2][3];
      for (int s = 0; s < 2; ++s) {
        for (int a = 0; a < 3; ++a) {
          fit[s][a] = RefitCubic(Coefficients(imu, s, a), t_ref, lo, hi, 35.0);
          if (imu.at(kSensors[s]).at("bias").at("orders").at(static_cast<size_t>(a)).get<int>() >
              3) {
            p << "# " << kSensors[s] << " " << kAxes[a] << ": calibd's order-"
              << imu.at(kSensors[s]).at("bias").at("orders").at(static_cast<size_t>(a)).get<int>()
              << " curve refit at order 3: largest difference over the range "
              << Num(fit[s][a].max_error, "%.3g") << (s ? " rad/s" : " m/s^2") << "\n";
          }
        }
      }
      p << "INS_TCAL" << n << "_ENABLE,1\n"
        << "INS_TCAL" << n << "_TMIN," << Num(lo, "%.2f") << "\n"
        << "INS_TCAL" << n << "_TMAX," << Num(hi, "%.2f") << "\n";
      for (int s = 0; s < 2; ++s) {
        for (int k = 0; k < 3; ++k) {
          for (int a = 0; a < 3; ++a) {
            p << "INS_TCAL" << n << "_" << (s ? "GYR" : "ACC") << k + 1 << "_"
              << static_cast<char>('X' + a) << "," << Num(fit[s][a].a[k] * 1e6) << "\n";
          }
        }
      }
    }
    *out = p.str();
    return Status::Ok();
  });
}

// PX4: TC_An_Xk_a / TC_Gn_Xk_a (a = 0, 1, 2 the axes), TREF, TMIN, TMAX, ID, in QGroundControl's
// lines "vehicle<TAB>component<TAB>name<TAB>value<TAB>type" (type 9 float, 6 int32).
Status ThermalResultToPx4(const json& result, const ExportContext& context, std::string* out) {
  return Guarded([&] {
    const json& imus = result.at("parameters").at("imus");
    if (imus.size() > 3) {
      return Status::NotDeterminable(
          "PX4 holds at most 3 thermal calibrations per sensor type; "
          "the result has " +
          std::to_string(imus.size()) + " IMUs");
    }
    int64_t device_id = 0;
    if (context.config.is_object() && context.config.contains("device_id")) {
      device_id = context.config.at("device_id").get<int64_t>();
    }
    std::ostringstream p;
    p << "# Onboard parameters for Vehicle 1\n# calibd thermal job " << context.job_id
      << " of device '" << CommentSafe(context.device) << "', " << CommentSafe(context.finished_at)
      << "\n# Scale curves are not held by PX4: left out. TC_An_X0_a is the accelerometer bias at"
         " TREF where the log's orientations determine it (opposite faces), else 0: the"
         " room-temperature calibration supplies it.\n"
      << "# MAV ID\tCOMPONENT ID\tPARAM NAME\tVALUE\t(TYPE)\n";
    auto line = [&](const std::string& name, const std::string& value, int type) {
      p << "1\t1\t" << name << "\t" << value << "\t" << type << "\n";
    };
    line("TC_A_ENABLE", "1", 6);
    line("TC_G_ENABLE", "1", 6);
    for (size_t i = 0; i < imus.size(); ++i) {
      const json& imu = imus[i];
      const double t_ref = imu.at("t_ref").get<double>(), lo = imu.at("t_min").get<double>(),
                   hi = imu.at("t_max").get<double>();
      for (int s = 0; s < 2; ++s) {
        const std::string base = std::string("TC_") + (s ? "G" : "A") + std::to_string(i);
        const json& at = imu.at(kSensors[s]).at("bias").at("at_t_ref");
        line(base + "_ID", std::to_string(device_id), 6);
        for (int a = 0; a < 3; ++a) {
          const FirmwareCubic f = RefitCubic(Coefficients(imu, s, a), t_ref, lo, hi, t_ref);
          const int order =
              imu.at(kSensors[s]).at("bias").at("orders").at(static_cast<size_t>(a)).get<int>();
          if (order > 3) {
            p << "# " << base << " axis " << a << ": calibd's order-" << order
              << " curve refit at order 3: largest difference over the range "
              << Num(f.max_error, "%.3g") << (s ? " rad/s" : " m/s^2") << "\n";
          }
          // X0: the bias at TREF where known, plus the refit's constant (0 for order <= 3).
          const double x0 = (at.is_array() && at.at(static_cast<size_t>(a)).is_number()
                                 ? at.at(static_cast<size_t>(a)).get<double>()
                                 : 0.0) +
                            f.constant;
          const std::string ax = "_" + std::to_string(a);
          line(base + "_X0" + ax, Num(x0), 9);
          for (int k = 0; k < 3; ++k)
            line(base + "_X" + std::to_string(k + 1) + ax, Num(f.a[k]), 9);
        }
        line(base + "_TREF", Num(t_ref, "%.3f"), 9);
        line(base + "_TMIN", Num(lo, "%.3f"), 9);
        line(base + "_TMAX", Num(hi, "%.3f"), 9);
      }
    }
    *out = p.str();
    return Status::Ok();
  });
}

}  // namespace calibd::server
