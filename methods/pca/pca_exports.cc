// Exports of a pca result (methods/pca/pca_method.h): CSV and the C header.
#include <Eigen/Dense>
#include <cmath>
#include <sstream>
#include <string>

#include "methods/export_util.h"
#include "methods/pca/pca_method.h"
#include "methods/pca/pca_result.h"

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

// The typed result of an export, or kInternal with the reader's message (a stored result that
// does not read, or a failed run's partial document without parameters).
Status ReadForExport(const json& result, results::PcaResult* out) {
  const Status s = results::FromJson(result, out);
  if (!s.ok()) return UnreadableStoredResult(s);
  if (!out->parameters || !out->uncertainty) {
    return Status::Internal("stored pca result has no parameters (a failed run's diagnostics)");
  }
  return Status::Ok();
}

// Per-sensor standard deviations (as StdArray1 of methods/export_util.h): the array when every
// entry is defined, else a comment naming the sensors whose σ is undefined (never a made-up 0).
void StdArray(HeaderWriter* w, const std::string& name, const std::vector<double>& values,
              const char* key, const std::vector<std::string>& names, const std::string& comment) {
  std::string undefined;
  for (size_t i = 0; i < names.size(); ++i) {
    if (!std::isfinite(values[i])) undefined += (undefined.empty() ? "" : ", ") + names[i];
  }
  if (undefined.empty()) {
    w->Array1(name, values, comment);
  } else {
    w->out() << "/* " << w->macro() << name << " is not written: " << CComment(key)
             << " is undefined for " << CComment(undefined) << " (see format=json). */\n";
  }
}

Status PcaHeader(const results::PcaResult& result, HeaderWriter* w) {
  const results::PcaParameters& params = *result.parameters;
  const std::vector<results::PcaSensor>& sensors = params.sensors;
  if (sensors.empty()) return Status::Internal("stored pca result has no parameters.sensors");
  const size_t m = sensors.size();
  // FromJson checked dimension >= 1 and that every sensitivity and axis has d components.
  if (static_cast<size_t>(params.dimension) > m) {
    return Status::Internal("stored pca result has a bad dimension");
  }
  const size_t d = static_cast<size_t>(params.dimension);
  std::vector<std::string> names;
  std::vector<std::vector<double>> sensitivity(m), axis(m);
  std::vector<double> bias(m), scale(m);
  Eigen::MatrixXd a(m, d);
  auto all_finite = [](const std::vector<double>& v) {
    for (double x : v) {
      if (!std::isfinite(x)) return false;
    }
    return true;
  };
  for (size_t i = 0; i < m; ++i) {
    const results::PcaSensor& s = sensors[i];
    names.push_back(s.name);
    if (!all_finite(s.sensitivity) || !all_finite(s.axis) || !std::isfinite(s.scale) ||
        !std::isfinite(s.bias)) {
      return Status::NotDeterminable("the pca result of sensor '" + names.back() +
                                     "' has undefined parameters: no C header can be written");
    }
    sensitivity[i] = s.sensitivity;
    axis[i] = s.axis;
    scale[i] = s.scale;
    bias[i] = s.bias;
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
  const bool known = params.magnitude_known;
  const std::string frame = results::Name(params.frame);
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
  // FromJson checked: one uncertainty entry per sensor, in the same order.
  std::vector<double> scale_std, axis_std, bias_std;
  for (const results::PcaSensorStd& u : result.uncertainty->sensors) {
    scale_std.push_back(u.scale_std);
    axis_std.push_back(u.axis_std_rad);
    bias_std.push_back(u.bias_std);
  }
  StdArray(w, "SCALE_STD", scale_std, "scale_std", names, "1 sigma of SCALE");
  StdArray(w, "AXIS_STD_RAD", axis_std, "axis_std_rad", names, "1 sigma of the axis angle, rad");
  StdArray(w, "BIAS_STD", bias_std, "bias_std", names, "1 sigma of BIAS, reading units");
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
  results::PcaResult typed;
  Status s = ReadForExport(result, &typed);
  if (!s.ok()) return s;
  const results::PcaParameters& params = *typed.parameters;
  const std::vector<results::PcaSensorStd>& stds = typed.uncertainty->sensors;
  std::ostringstream csv;
  const size_t d = static_cast<size_t>(params.dimension);
  const auto axes = AxisNames(d);
  csv << "name,scale,scale_std";
  for (const auto& a : axes) csv << ",axis_" << a;
  csv << ",axis_std_rad,bias,bias_std";
  for (const auto& a : axes) csv << ",sensitivity_" << a;
  csv << "\n";
  // Numbers as the JSON holds them (an undefined value, null there, is an empty cell).
  auto number = [](double x) { return CsvNumber(results::Num(x)); };
  for (size_t i = 0; i < params.sensors.size(); ++i) {
    const results::PcaSensor& p = params.sensors[i];
    const results::PcaSensorStd& u = stds[i];  // FromJson checked: one per sensor, same order
    csv << CsvField(p.name) << "," << number(p.scale) << "," << number(u.scale_std);
    for (size_t k = 0; k < d; ++k) csv << "," << number(p.axis[k]);
    csv << "," << number(u.axis_std_rad) << "," << number(p.bias) << "," << number(u.bias_std);
    for (size_t k = 0; k < d; ++k) csv << "," << number(p.sensitivity[k]);
    csv << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status PcaResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  results::PcaResult typed;
  Status s = ReadForExport(result, &typed);
  if (!s.ok()) return s;
  // WriteCHeader writes the frame; the body comes from the typed result (its JSON arguments,
  // the untyped parameters and uncertainty, are not read).
  return WriteCHeader(
      result, context, "pca", kPcaModel,
      [&](const json&, const json&, HeaderWriter* w) { return PcaHeader(typed, w); }, out);
}

}  // namespace calibd::server
