// Exports of an array result (server/array_method.h): CSV and the C header.
#include <Eigen/Dense>
#include <sstream>
#include <string>

#include "server/array_method.h"
#include "server/export_util.h"
#include "server/imu_method.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kArrayModel =
    " * Model (array): accelerometer triad k at position r_k reads\n"
    " * y_a,k = s + (Omega(w)^2 + Omega(w'))r_k, the gyroscopes y_g = w (s the specific\n"
    " * force at the origin, w the angular rate, Omega(x) the cross-product matrix).\n"
    " * The parameters are the positions POSITION (data, nothing to apply per reading).\n"
    " * With model full, per IMU a = ACCEL_MATRIX (y_a - ACCEL_BIAS),\n"
    " * omega = GYRO_MATRIX (y_g - GYRO_BIAS), applied by *_array_apply().\n";

Status ArrayHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& positions = JsonAt(params, "positions");
  if (!positions.is_array() || positions.empty()) {
    return Status::Internal("stored array result has no parameters.positions");
  }
  const size_t k = positions.size();
  std::vector<std::string> names;
  std::vector<std::vector<double>> position(k), offset(k), stds;
  for (size_t i = 0; i < k; ++i) {
    const json& p = positions[i];
    names.push_back(JsonAt(p, "name").is_string() ? p["name"].get<std::string>() : "");
    if (!Numbers(JsonAt(p, "position"), 3, &position[i]) ||
        !Numbers(JsonAt(p, "offset"), 3, &offset[i])) {
      return Status::NotDeterminable("the array result of triad '" + names.back() +
                                     "' has an undefined position: no C header can be written");
    }
  }
  w->Define("TRIADS", std::to_string(k), "accelerometer triads K");
  w->Define("REFERENCE",
            std::to_string(JsonAt(params, "reference").is_number_integer()
                               ? params["reference"].get<int>()
                               : 0),
            "index of the reference triad, held at its nominal position");
  w->Names("NAMES", names);
  w->Array2("POSITION", position, 3, "r_k: triad positions, metres, nominal geometry frame");
  w->Array2("OFFSET", offset, 3, "offset from the nominal position, metres");
  const json& upos = JsonAt(unc, "positions");
  bool all = upos.is_array() && upos.size() == k;
  for (size_t i = 0; all && i < k; ++i) {
    std::vector<double> s;
    all = Numbers(JsonAt(upos[i], "std"), 3, &s);
    stds.push_back(s);
  }
  if (all) {
    w->Array2("POSITION_STD", stds, 3, "1 sigma (Cramer-Rao bound), metres");
  } else {
    w->out() << "/* " << w->macro()
             << "POSITION_STD is not written: some sigma are undefined (see format=json). */\n";
  }
  return Status::Ok();
}

}  // namespace

Status ArrayResultToCsv(const json& result, std::string* out) {
  std::ostringstream csv;
  const json& params = JsonAt(result, "parameters");
  const json& unc = JsonAt(result, "uncertainty");
  const json& positions = JsonAt(params, "positions");
  if (!positions.is_array()) {
    return Status::Internal("stored array result has no parameters.positions");
  }
  const json& upos = JsonAt(unc, "positions");
  csv << "name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z\n";
  for (size_t i = 0; i < positions.size(); ++i) {
    const json& p = positions[i];
    const json& u = upos.is_array() && i < upos.size() ? upos[i] : json();
    const json& name = JsonAt(p, "name");
    csv << CsvField(name.is_string() ? name.get<std::string>() : "");
    for (const char* key : {"position", "offset"}) {
      const json& v = JsonAt(p, key);
      for (size_t k = 0; k < 3; ++k)
        csv << "," << (v.is_array() && k < v.size() ? CsvNumber(v[k]) : "");
    }
    const json& std = JsonAt(u, "std");
    for (size_t k = 0; k < 3; ++k)
      csv << "," << (std.is_array() && k < std.size() ? CsvNumber(std[k]) : "");
    csv << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status ArrayResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return WriteCHeader(
      result, context, "array", kArrayModel,
      [&](const json& params, const json& unc, HeaderWriter* w) {
        Status s = ArrayHeader(params, unc, w);
        // An array result of the full model carries per-IMU intrinsics as well.
        if (s.ok() && JsonAt(params, "imus").is_array()) {
          s = ImuHeader(params, unc, "IMU_", w);
        }
        return s;
      },
      out);
}

}  // namespace calibd::server
