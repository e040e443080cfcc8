// Exports of an array result (methods/array/array_method.h): CSV and the C header.
#include <Eigen/Dense>
#include <sstream>
#include <string>

#include "methods/array/array_method.h"
#include "methods/array/array_result.h"
#include "methods/export_util.h"
#include "methods/imu/imu_method.h"

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

// An array result read typed; kInternal with the reader's message when it does not read (a stored
// result is the server's own writing) or is a failed run's partial diagnostics.
Status ReadArrayResult(const json& result, results::ArrayResult* out) {
  Status s = results::FromJson(result, out);
  if (!s.ok()) return UnreadableStoredResult(s);
  if (!out->parameters || !out->uncertainty)
    return Status::Internal("stored array result has no parameters (a failed run)");
  return Status::Ok();
}

std::vector<double> Values(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

Status ArrayHeader(const results::ArrayResult& r, HeaderWriter* w) {
  const results::ArrayParameters& params = *r.parameters;
  const std::vector<results::ArrayPositionStd>& upos = r.uncertainty->positions;
  if (params.positions.empty()) {
    return Status::Internal("stored array result has no parameters.positions");
  }
  const size_t k = params.positions.size();
  std::vector<std::string> names;
  std::vector<std::vector<double>> position, offset, stds;
  bool offsets = true;  // false: some offset is unknown (a full-model result without
                        // parameters.positions, stored by an earlier calibd)
  for (const results::ArrayPosition& p : params.positions) {
    names.push_back(p.name);
    if (!p.position.allFinite()) {
      return Status::NotDeterminable("the array result of triad '" + p.name +
                                     "' has an undefined position: no C header can be written");
    }
    offsets = offsets && p.offset.allFinite();
    position.push_back(Values(p.position));
    offset.push_back(Values(p.offset));
  }
  w->Define("TRIADS", std::to_string(k), "accelerometer triads K");
  w->Define("REFERENCE", std::to_string(params.reference),
            "index of the reference triad, held at its nominal position");
  w->Names("NAMES", names);
  w->Array2("POSITION", position, 3, "r_k: triad positions, metres, nominal geometry frame");
  if (offsets) {
    w->Array2("OFFSET", offset, 3, "offset from the nominal position, metres");
  } else {
    w->out() << "/* " << w->macro()
             << "OFFSET is not written: the result does not give every offset from the nominal "
                "position. */\n";
  }
  bool all = upos.size() == k;
  for (size_t i = 0; all && i < k; ++i) {
    all = upos[i].std.allFinite();
    stds.push_back(Values(upos[i].std));
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
  results::ArrayResult r;
  if (Status s = ReadArrayResult(result, &r); !s.ok()) return s;
  const std::vector<results::ArrayPositionStd>& upos = r.uncertainty->positions;
  std::ostringstream csv;
  csv << "name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z\n";
  for (size_t i = 0; i < r.parameters->positions.size(); ++i) {
    const results::ArrayPosition& p = r.parameters->positions[i];
    csv << CsvField(p.name);
    for (const Eigen::Vector3d* v : {&p.position, &p.offset})
      for (int k = 0; k < 3; ++k) csv << "," << CsvNumber(results::Num((*v)(k)));
    for (int k = 0; k < 3; ++k)
      csv << "," << (i < upos.size() ? CsvNumber(results::Num(upos[i].std(k))) : "");
    csv << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status ArrayResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  results::ArrayResult r;
  if (Status s = ReadArrayResult(result, &r); !s.ok()) return s;
  return WriteCHeader(
      result, context, "array", kArrayModel,
      [&](const json& params, const json& unc, HeaderWriter* w) {
        Status s = ArrayHeader(r, w);
        // An array result of the full model carries per-IMU intrinsics as well: written by the
        // imu method's writer (methods/imu/imu_exports.cc), which reads the same per-IMU blocks.
        if (s.ok() && r.full) s = ImuHeader(params, unc, "IMU_", w);
        return s;
      },
      out);
}

}  // namespace calibd::server
