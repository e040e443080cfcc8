// Exports of a pca result (server/pca_method.h): CSV and the C header.
#include <Eigen/Dense>
#include <sstream>
#include <string>

#include "server/export_util.h"
#include "server/pca_method.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kPcaModel =
    " * Model (pca): the raw reading of sensor i is r_i = a_i . v + b_i, for the field v\n"
    " * (DIMENSION components), a_i = SCALE_i * AXIS_i the sensitivity vector, b_i the "
    "bias.\n"
    " * The calibrated field from one raw reading of all SENSORS sensors is the least-\n"
    " * squares inverse v = (A^T A)^-1 A^T (r - b), A the SENSORS x DIMENSION matrix of\n"
    " * rows a_i: INVERSE below, applied by *_pca_apply().\n";

Status PcaHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& sensors = JsonAt(params, "sensors");
  if (!sensors.is_array() || sensors.empty()) {
    return Status::Internal("stored pca result has no parameters.sensors");
  }
  const size_t m = sensors.size();
  const json& dim = JsonAt(params, "dimension");
  const int64_t d_json = dim.is_number_integer() ? dim.get<int64_t>() : 3;
  if (d_json < 1 || d_json > static_cast<int64_t>(m)) {
    return Status::Internal("stored pca result has a bad dimension");
  }
  const size_t d = static_cast<size_t>(d_json);
  std::vector<std::string> names;
  std::vector<std::vector<double>> sensitivity(m), axis(m);
  std::vector<double> bias(m, 0.0), scale(m);
  Eigen::MatrixXd a(m, d);
  for (size_t i = 0; i < m; ++i) {
    const json& s = sensors[i];
    names.push_back(JsonAt(s, "name").is_string() ? s["name"].get<std::string>() : "");
    std::vector<double> b;
    if (!Numbers(JsonAt(s, "sensitivity"), d, &sensitivity[i]) ||
        !Numbers(JsonAt(s, "axis"), d, &axis[i]) || !JsonAt(s, "scale").is_number()) {
      return Status::NotDeterminable("the pca result of sensor '" + names.back() +
                                     "' has undefined parameters: no C header can be written");
    }
    scale[i] = s["scale"].get<double>();
    if (JsonAt(s, "bias").is_number()) bias[i] = s["bias"].get<double>();
    for (size_t k = 0; k < d; ++k) a(i, k) = sensitivity[i][k];
  }
  // The least-squares inverse of reading = A v + b: v = (AᵀA)⁻¹Aᵀ (reading − b).
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd sv = svd.singularValues();
  if (!(sv(d - 1) > 1e-12 * sv(0))) {
    return Status::NotDeterminable(
        "the sensitivity vectors do not span the field's dimensions: no inverse can be written");
  }
  const Eigen::MatrixXd pinv =
      svd.matrixV() * sv.cwiseInverse().asDiagonal() * svd.matrixU().transpose();
  std::vector<std::vector<double>> inverse(d, std::vector<double>(m));
  for (size_t k = 0; k < d; ++k)
    for (size_t i = 0; i < m; ++i)
      inverse[k][i] = pinv(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(i));
  const bool known =
      JsonAt(params, "magnitude_known").is_boolean() && params["magnitude_known"].get<bool>();
  const std::string frame =
      JsonAt(params, "frame").is_string() ? params["frame"].get<std::string>() : "";
  w->Define("SENSORS", std::to_string(m), "m single-axis sensors");
  w->Define("DIMENSION", std::to_string(d), "d components of the field v");
  w->Define("MAGNITUDE_KNOWN", known ? "1" : "0",
            known ? "field in the units of the configured magnitude"
                  : "magnitude unknown: the field and scale factors are relative");
  w->Names("NAMES", names);
  w->Array2("SENSITIVITY", sensitivity, d,
            "a_i = scale_i * axis_i, one row per sensor (" + frame + " frame)");
  w->Array2("AXIS", axis, d, "unit axis of each sensor (" + frame + " frame)");
  w->Array1("SCALE", scale, "scale factor |a_i|, reading units per field unit");
  w->Array1("BIAS", bias, "b_i, reading units (0: none estimated or removed)");
  w->Array2("INVERSE", inverse, m,
            "(A^T A)^-1 A^T, d x m: the least-squares field from the m bias-free readings");
  const json& usens = JsonAt(unc, "sensors");
  StdArray1(w, "SCALE_STD", usens, "scale_std", names, "1 sigma of SCALE");
  StdArray1(w, "AXIS_STD_RAD", usens, "axis_std_rad", names, "1 sigma of the axis angle, rad");
  StdArray1(w, "BIAS_STD", usens, "bias_std", names, "1 sigma of BIAS, reading units");
  std::ostringstream& h = w->out();
  const std::string& M = w->macro();
  h << "\n/* The field v (DIMENSION components) from one raw reading of each of the SENSORS\n"
       " * sensors: v = INVERSE (reading - BIAS). */\n"
    << "static inline void " << w->func() << "apply(const double reading[" << m
    << "], double field[" << d << "]) {\n"
    << "  int k, i;\n"
    << "  for (k = 0; k < " << M << "DIMENSION; ++k) {\n"
    << "    double v = 0.0;\n"
    << "    for (i = 0; i < " << M << "SENSORS; ++i) v += " << M << "INVERSE[k][i] * (reading[i] - "
    << M << "BIAS[i]);\n"
    << "    field[k] = v;\n"
    << "  }\n"
    << "}\n";
  return Status::Ok();
}

}  // namespace

Status PcaResultToCsv(const json& result, std::string* out) {
  std::ostringstream csv;
  const json& params = JsonAt(result, "parameters");
  const json& unc = JsonAt(result, "uncertainty");
  const json& sensors = JsonAt(params, "sensors");
  if (!sensors.is_array()) return Status::Internal("stored pca result has no parameters.sensors");
  const size_t d = JsonAt(params, "dimension").is_number() ? params["dimension"].get<size_t>() : 3;
  const auto axes = AxisNames(d);
  csv << "name,scale,scale_std";
  for (const auto& a : axes) csv << ",axis_" << a;
  csv << ",axis_std_rad,bias,bias_std";
  for (const auto& a : axes) csv << ",sensitivity_" << a;
  csv << "\n";
  const json& usens = JsonAt(unc, "sensors");
  for (size_t i = 0; i < sensors.size(); ++i) {
    const json& s = sensors[i];
    const json& u = usens.is_array() && i < usens.size() ? usens[i] : json();
    const json& name = JsonAt(s, "name");
    csv << CsvField(name.is_string() ? name.get<std::string>() : "") << ","
        << CsvNumber(JsonAt(s, "scale")) << "," << CsvNumber(JsonAt(u, "scale_std"));
    for (size_t k = 0; k < d; ++k) {
      const json& axis = JsonAt(s, "axis");
      csv << "," << (axis.is_array() && k < axis.size() ? CsvNumber(axis[k]) : "");
    }
    csv << "," << CsvNumber(JsonAt(u, "axis_std_rad")) << "," << CsvNumber(JsonAt(s, "bias")) << ","
        << CsvNumber(JsonAt(u, "bias_std"));
    for (size_t k = 0; k < d; ++k) {
      const json& sens = JsonAt(s, "sensitivity");
      csv << "," << (sens.is_array() && k < sens.size() ? CsvNumber(sens[k]) : "");
    }
    csv << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status PcaResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return WriteCHeader(
      result, context, "pca", kPcaModel,
      [&](const json& params, const json& unc, HeaderWriter* w) {
        return PcaHeader(params, unc, w);
      },
      out);
}

}  // namespace calibd::server
