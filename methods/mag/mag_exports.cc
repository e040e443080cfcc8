// Exports of a mag result (methods/mag/mag_method.h): csv, a C99 header, ArduPilot's COMPASS_*
// and PX4's CAL_MAGn_* parameter files.
#include <cmath>
#include <cstdio>
#include <sstream>

#include "methods/export_util.h"
#include "methods/mag/mag_method.h"

namespace calibd::server {

namespace {

const char kAxes[3] = {'X', 'Y', 'Z'};

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
    return Status::Internal(std::string("the mag result lacks its SPEC keys: ") + e.what());
  }
}

Eigen::Vector3d Vec3(const json& v) {
  return Eigen::Vector3d(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>());
}

Eigen::Matrix3d Mat3(const json& m) {
  Eigen::Matrix3d out;
  for (int r = 0; r < 3; ++r) out.row(r) = Vec3(m.at(r)).transpose();
  return out;
}

// What the firmware files carry of one magnetometer: the hard iron in µT and the dimensionless
// symmetric matrix M = P k / (µT per unit) (mag_method.h), so M (raw − h) is the field in the
// raw reading's own scale.
struct FirmwareMag {
  Eigen::Vector3d hard_iron_ut;
  Eigen::Matrix3d matrix;
};

FirmwareMag ForFirmware(const json& mag) {
  const double per_unit = mag.at("microtesla_per_unit").get<double>();
  const json& field = mag.at("field");
  // P maps reading units to µT with a field; without one, to a unit field.
  const double f = field.is_number() ? 1.0 : mag.at("field_estimate").get<double>();
  return {Vec3(mag.at("hard_iron")) * per_unit, Mat3(mag.at("soft_iron_symmetric")) * f / per_unit};
}

const char* const kFirmwareComment =
    "Both firmwares hold only a symmetric matrix in the magnetometer's own axes: the file carries "
    "P (the soft iron without the rotation to the accelerometer frame), so the alignment is not "
    "carried; the orientation parameters are not written (leave them at 0, rotation none).";

// The firmware device id of magnetometer k: the result's (config device_id, else the log
// stream's; see methods/mag/mag_method.cc SetDeviceId), else (none known to the run, or a result
// stored before it carried one) the export's config device_id (a number: m0's; an array: one per
// magnetometer); -1: none.
int64_t DeviceId(const json& mags, const ExportContext& context, size_t k) {
  if (const json& m = mags.at(k);
      m.contains("device_id") && m.at("device_id").is_number_integer()) {
    return m.at("device_id").get<int64_t>();
  }
  if (!context.config.is_object() || !context.config.contains("device_id")) return -1;
  const json& id = context.config.at("device_id");
  if (id.is_array()) return k < id.size() ? id.at(k).get<int64_t>() : -1;
  return k == 0 ? id.get<int64_t>() : -1;
}

}  // namespace

Status MagResultToCsv(const json& result, std::string* out) {
  return Guarded([&] {
    std::ostringstream c;
    c << "name,mag_unit,hard_iron_x,hard_iron_y,hard_iron_z,hard_iron_std_x,hard_iron_std_y,"
         "hard_iron_std_z";
    for (const char* r : {"x", "y", "z"}) {
      for (const char* col : {"x", "y", "z"}) c << ",soft_iron_" << r << col;
    }
    c << ",dip,dip_std,field,field_estimate\n";
    const json& mags = result.at("parameters").at("mags");
    const json& unc = result.at("uncertainty").at("mags");
    for (size_t i = 0; i < mags.size(); ++i) {
      const json& m = mags[i];
      c << CsvField(m.at("name").get<std::string>()) << ","
        << CsvField(m.at("mag_unit").get<std::string>());
      for (int a = 0; a < 3; ++a) c << "," << CsvNumber(m.at("hard_iron").at(a));
      for (int a = 0; a < 3; ++a) c << "," << CsvNumber(unc[i].at("hard_iron_std").at(a));
      for (int r = 0; r < 3; ++r) {
        for (int col = 0; col < 3; ++col) c << "," << CsvNumber(m.at("soft_iron").at(r).at(col));
      }
      c << "," << CsvNumber(m.at("dip")) << "," << CsvNumber(unc[i].at("dip_std")) << ","
        << CsvNumber(m.at("field")) << "," << CsvNumber(m.at("field_estimate")) << "\n";
    }
    *out = c.str();
    return Status::Ok();
  });
}

Status MagResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return Guarded([&] {
    return WriteCHeader(
        result, context, "mag",
        " * m = S (y - h): y the raw reading (mag_unit), h the hard iron (reading units), S the\n"
        " * soft iron (uT per reading unit, or unit field per reading unit when no field was\n"
        " * given), m the field in the accelerometer frame where the alignment was estimated.",
        [&](const json& params, const json&, HeaderWriter* w) {
          for (const json& mag : params.at("mags")) {
            const std::string n = IdentifierStem(mag.at("name").get<std::string>());
            w->Array1(n + "_HARD_IRON", mag.at("hard_iron").get<std::vector<double>>(),
                      "h, reading units");
            std::vector<std::vector<double>> rows;
            for (const json& row : mag.at("soft_iron"))
              rows.push_back(row.get<std::vector<double>>());
            w->Array2(n + "_SOFT_IRON", rows, 3, "S, rows");
            const std::string m = w->macro() + n;
            w->out() << "/* The calibrated field of one raw reading. */\n"
                     << "static inline void " << w->func() << LowerCase(n)
                     << "_correct(const double raw[3], double field[3]) {\n"
                     << "  int r, c;\n"
                     << "  for (r = 0; r < 3; ++r) {\n"
                     << "    field[r] = 0;\n"
                     << "    for (c = 0; c < 3; ++c) field[r] += " << m
                     << "_SOFT_IRON[r][c] * (raw[c] - " << m << "_HARD_IRON[c]);\n"
                     << "  }\n}\n";
          }
          return Status::Ok();
        },
        out);
  });
}

Status MagResultToArduPilot(const json& result, const ExportContext& context, std::string* out) {
  return Guarded([&] {
    const json& mags = result.at("parameters").at("mags");
    if (mags.size() > 3) {
      return Status::NotDeterminable("ArduPilot holds at most 3 compasses; the result has " +
                                     std::to_string(mags.size()));
    }
    std::ostringstream p;
    p << "# ArduPilot compass calibration from calibd mag job " << context.job_id << " of device '"
      << CommentSafe(context.device) << "', " << CommentSafe(context.finished_at)
      << ".\n# Milligauss; the firmware applies mag = DIA/ODI matrix * (raw + OFS) "
         "(AP_Compass_Backend::correct_field).\n# "
      << kFirmwareComment << "\n";
    for (size_t i = 0; i < mags.size(); ++i) {
      const FirmwareMag f = ForFirmware(mags[i]);
      const std::string n = i == 0 ? "" : std::to_string(i + 1);
      const Eigen::Vector3d ofs = -10 * f.hard_iron_ut;  // µT -> mG
      const double odi[3] = {f.matrix(0, 1), f.matrix(0, 2), f.matrix(1, 2)};
      for (int a = 0; a < 3; ++a)
        p << "COMPASS_OFS" << n << "_" << kAxes[a] << "," << Num(ofs(a)) << "\n";
      for (int a = 0; a < 3; ++a) {
        p << "COMPASS_DIA" << n << "_" << kAxes[a] << "," << Num(f.matrix(a, a)) << "\n";
      }
      for (int a = 0; a < 3; ++a)
        p << "COMPASS_ODI" << n << "_" << kAxes[a] << "," << Num(odi[a]) << "\n";
      if (const int64_t id = DeviceId(mags, context, i); id >= 0) {
        p << "COMPASS_DEV_ID" << n << "," << id << "\n";
      } else {
        p << "# COMPASS_DEV_ID" << n
          << " not written (neither the log nor config device_id gives it): the firmware "
          << "applies these values only where it matches the compass's id; set it.\n";
      }
    }
    *out = p.str();
    return Status::Ok();
  });
}

Status MagResultToPx4(const json& result, const ExportContext& context, std::string* out) {
  return Guarded([&] {
    const json& mags = result.at("parameters").at("mags");
    if (mags.size() > 4) {
      return Status::NotDeterminable(
          "PX4 holds at most 4 magnetometer calibrations; the result "
          "has " +
          std::to_string(mags.size()));
    }
    std::ostringstream p;
    p << "# Onboard parameters for Vehicle 1\n# calibd mag job " << context.job_id << " of device '"
      << CommentSafe(context.device) << "', " << CommentSafe(context.finished_at)
      << "\n# Gauss; the firmware applies mag = SCALE/ODIAG matrix * (raw - OFF) "
         "(sensor_calibration/Magnetometer.hpp Correct), for the sensor whose CAL_MAGn_ID is "
         "set.\n# "
      << kFirmwareComment << "\n# MAV ID\tCOMPONENT ID\tPARAM NAME\tVALUE\t(TYPE)\n";
    for (size_t i = 0; i < mags.size(); ++i) {
      const FirmwareMag f = ForFirmware(mags[i]);
      const std::string base = "CAL_MAG" + std::to_string(i) + "_";
      const Eigen::Vector3d off = f.hard_iron_ut / 100;  // µT -> gauss
      const double odiag[3] = {f.matrix(0, 1), f.matrix(0, 2), f.matrix(1, 2)};
      auto line = [&](const std::string& name, double value) {
        p << "1\t1\t" << base << name << "\t" << Num(value) << "\t9\n";
      };
      for (int a = 0; a < 3; ++a) line(std::string(1, kAxes[a]) + "OFF", off(a));
      for (int a = 0; a < 3; ++a) line(std::string(1, kAxes[a]) + "SCALE", f.matrix(a, a));
      for (int a = 0; a < 3; ++a) line(std::string(1, kAxes[a]) + "ODIAG", odiag[a]);
      if (const int64_t id = DeviceId(mags, context, i); id >= 0) {
        p << "1\t1\t" << base << "ID\t" << id << "\t6\n";
      } else {
        p << "# " << base << "ID not written (neither the log nor config device_id gives it): the "
          << "firmware applies these values only to the sensor whose id it holds; set it.\n";
      }
    }
    *out = p.str();
    return Status::Ok();
  });
}

}  // namespace calibd::server
