#include "server/exports.h"

#include <Eigen/Dense>
#include <cstdio>
#include <sstream>

#include "server/openvins_yaml.h"

namespace calibd::server {

using nlohmann::json;

namespace {

std::string Num(const json& v) {
  if (!v.is_number()) return "";  // null: undefined value, an empty CSV cell
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
  return buf;
}

// CSV field: quoted when it holds a comma, quote or line break.
std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

// For a // comment: printable ASCII only.
std::string CommentSafe(const std::string& s) {
  std::string out;
  for (unsigned char c : s) out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  return out;
}

std::string CString(const std::string& s) {
  std::string out = "\"";
  for (unsigned char c : s) {
    if (c == '"' || c == '\\' || c == '?') {  // '?': no trigraph (C99) can form
      out += '\\';
      out += static_cast<char>(c);
    } else if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\%03o", c);
      out += buf;
    }
  }
  return out + "\"";
}

std::vector<std::string> AxisNames(size_t d) {
  static const char* xyz[] = {"x", "y", "z"};
  std::vector<std::string> names;
  for (size_t k = 0; k < d; ++k) names.push_back(d <= 3 ? xyz[k] : std::to_string(k + 1));
  return names;
}

const json& Get(const json& obj, const char* key) {
  static const json kNull;
  if (!obj.is_object()) return kNull;
  auto it = obj.find(key);
  return it == obj.end() ? kNull : *it;
}

}  // namespace

Status ResultToCsv(const json& result, std::string* out) {
  std::ostringstream csv;
  const std::string method =
      Get(result, "method").is_string() ? result["method"].get<std::string>() : "";
  const json& params = Get(result, "parameters");
  const json& unc = Get(result, "uncertainty");
  if (method == "pca") {
    const json& sensors = Get(params, "sensors");
    if (!sensors.is_array()) return Status::Internal("stored pca result has no parameters.sensors");
    const size_t d = Get(params, "dimension").is_number() ? params["dimension"].get<size_t>() : 3;
    const auto axes = AxisNames(d);
    csv << "name,scale,scale_std";
    for (const auto& a : axes) csv << ",axis_" << a;
    csv << ",axis_std_rad,bias,bias_std";
    for (const auto& a : axes) csv << ",sensitivity_" << a;
    csv << "\n";
    const json& usens = Get(unc, "sensors");
    for (size_t i = 0; i < sensors.size(); ++i) {
      const json& s = sensors[i];
      const json& u = usens.is_array() && i < usens.size() ? usens[i] : json();
      const json& name = Get(s, "name");
      csv << CsvField(name.is_string() ? name.get<std::string>() : "") << ","
          << Num(Get(s, "scale")) << "," << Num(Get(u, "scale_std"));
      for (size_t k = 0; k < d; ++k) {
        const json& axis = Get(s, "axis");
        csv << "," << (axis.is_array() && k < axis.size() ? Num(axis[k]) : "");
      }
      csv << "," << Num(Get(u, "axis_std_rad")) << "," << Num(Get(s, "bias")) << ","
          << Num(Get(u, "bias_std"));
      for (size_t k = 0; k < d; ++k) {
        const json& sens = Get(s, "sensitivity");
        csv << "," << (sens.is_array() && k < sens.size() ? Num(sens[k]) : "");
      }
      csv << "\n";
    }
  } else if (method == "array") {
    const json& positions = Get(params, "positions");
    if (!positions.is_array()) {
      return Status::Internal("stored array result has no parameters.positions");
    }
    const json& upos = Get(unc, "positions");
    csv << "name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z\n";
    for (size_t i = 0; i < positions.size(); ++i) {
      const json& p = positions[i];
      const json& u = upos.is_array() && i < upos.size() ? upos[i] : json();
      const json& name = Get(p, "name");
      csv << CsvField(name.is_string() ? name.get<std::string>() : "");
      for (const char* key : {"position", "offset"}) {
        const json& v = Get(p, key);
        for (size_t k = 0; k < 3; ++k)
          csv << "," << (v.is_array() && k < v.size() ? Num(v[k]) : "");
      }
      const json& std = Get(u, "std");
      for (size_t k = 0; k < 3; ++k)
        csv << "," << (std.is_array() && k < std.size() ? Num(std[k]) : "");
      csv << "\n";
    }
  } else if (method == "imu") {
    const json& imus = Get(params, "imus");
    if (!imus.is_array()) return Status::Internal("stored imu result has no parameters.imus");
    const json& uimus = Get(unc, "imus");
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
      const json& name = Get(imus[i], "name");
      for (const char* sensor : {"accelerometer", "gyroscope"}) {
        const json& p = Get(imus[i], sensor);
        const json& ps = Get(u, sensor);
        csv << CsvField(name.is_string() ? name.get<std::string>() : "") << "," << sensor;
        auto vec = [&](const json& v) {
          for (size_t k = 0; k < 3; ++k)
            csv << "," << (v.is_array() && k < v.size() ? Num(v[k]) : "");
        };
        auto mat = [&](const json& m) {
          for (size_t r = 0; r < 3; ++r) vec(m.is_array() && r < m.size() ? m[r] : json());
        };
        vec(Get(p, "bias"));
        vec(Get(p, "scale"));
        mat(Get(p, "matrix"));
        vec(Get(ps, "bias_std"));
        vec(Get(ps, "scale_std"));
        mat(Get(ps, "misalignment_std"));
        csv << "\n";
      }
    }
  } else if (method == "noise") {
    const json& channels = Get(params, "channels");
    if (!channels.is_array()) return Status::Internal("stored noise result has no channels");
    const json& uch = Get(unc, "channels");
    csv << "name,unit,white_noise,white_noise_std,bias_instability,bias_instability_std,"
           "bias_instability_tau,random_walk,random_walk_std\n";
    for (size_t i = 0; i < channels.size(); ++i) {
      const json& c = channels[i];
      const json& u = uch.is_array() && i < uch.size() ? uch[i] : json();
      const json& name = Get(c, "name");
      const json& unit = Get(c, "unit");
      // A term the log could not show stays empty (null in JSON), never 0.
      csv << CsvField(name.is_string() ? name.get<std::string>() : "") << ","
          << CsvField(unit.is_string() ? unit.get<std::string>() : "") << ","
          << Num(Get(c, "white_noise")) << "," << Num(Get(u, "white_noise_std")) << ","
          << Num(Get(c, "bias_instability")) << "," << Num(Get(u, "bias_instability_std")) << ","
          << Num(Get(c, "bias_instability_tau")) << "," << Num(Get(c, "random_walk")) << ","
          << Num(Get(u, "random_walk_std")) << "\n";
    }
  } else {
    return Status::Internal("stored result has an unknown method");
  }
  *out = csv.str();
  return Status::Ok();
}

Status ResultToKalibrYaml(const json& result, const ExportContext& context, std::string* out) {
  const std::string method =
      Get(result, "method").is_string() ? result["method"].get<std::string>() : "";
  if (method == "imu") return ImuResultToOpenVinsYaml(result, context, out);
  if (method != "noise") {
    return Status::InvalidInput(
               "format=yaml is available for noise results (Kalibr imu.yaml) and imu results "
               "(OpenVINS kalibr_imu_chain.yaml)")
        .WithField("format");
  }
  const json& channels = Get(Get(result, "parameters"), "channels");
  if (!channels.is_array()) return Status::Internal("stored noise result has no channels");
  // Per sensor type the largest of its axes (Kalibr takes one figure for all three; the largest
  // keeps a filter from trusting the sensor more than its worst axis allows).
  struct Worst {
    double value = -1;
    std::string axis;
    std::vector<std::string> missing;
  };
  Worst worst[2][2];  // [accelerometer, gyroscope][white_noise, random_walk]
  bool seen[2] = {false, false};
  for (const json& c : channels) {
    const std::string name = Get(c, "name").is_string() ? c["name"].get<std::string>() : "";
    if (name.empty() || (name[0] != 'a' && name[0] != 'g')) continue;
    const int type = name[0] == 'a' ? 0 : 1;
    seen[type] = true;
    const char* keys[2] = {"white_noise", "random_walk"};
    for (int k = 0; k < 2; ++k) {
      const json& v = Get(c, keys[k]);
      if (!v.is_number()) {
        worst[type][k].missing.push_back(name);
      } else if (v.get<double>() > worst[type][k].value) {
        worst[type][k].value = v.get<double>();
        worst[type][k].axis = name;
      }
    }
  }
  std::ostringstream y;
  y << "# Kalibr IMU noise model (imu.yaml), from calibd noise job " << context.job_id
    << " of device '" << CommentSafe(context.device) << "', finished "
    << CommentSafe(context.finished_at) << ".\n"
    << "# Each figure is the largest over the sensor's axes; the Allan deviation, the other\n"
    << "# axes and the 1-sigma uncertainties are in format=json.\n";
  const char* type_names[2] = {"accelerometer", "gyroscope"};
  const char* units[2][2] = {{"m/s^2/sqrt(Hz)", "m/s^3/sqrt(Hz)"},
                             {"rad/s/sqrt(Hz)", "rad/s^2/sqrt(Hz)"}};
  const char* keys[2] = {"noise_density", "random_walk"};
  for (int type = 0; type < 2; ++type) {
    if (!seen[type]) continue;
    for (int k = 0; k < 2; ++k) {
      const Worst& w = worst[type][k];
      if (!w.missing.empty()) {
        std::string list;
        for (const auto& m : w.missing) list += (list.empty() ? "" : ", ") + m;
        return Status::NotDeterminable(
            std::string("the log does not show the ") + (k == 0 ? "white noise" : "random walk") +
            " of " + list + " (see the result's warnings for how long a log would): Kalibr's " +
            type_names[type] + "_" + keys[k] + " cannot be written");
      }
      y << type_names[type] << "_" << keys[k] << ": " << Num(json(w.value)) << "  # "
        << units[type][k] << ", " << w.axis << "\n";
    }
  }
  const json& rate = Get(Get(result, "diagnostics"), "rate");
  y << "rostopic: /imu0\n"
    << "update_rate: " << Num(rate) << "  # Hz\n";
  *out = y.str();
  return Status::Ok();
}

namespace {

// For a /* */ comment of the C header: printable ASCII, and no "*/" or "/*" (a serial such as
// "x*/ int y; /*" must not end the comment or open another one).
std::string CComment(const std::string& s) {
  std::string out;
  for (char c : CommentSafe(s)) {
    if (!out.empty() && ((out.back() == '*' && c == '/') || (out.back() == '/' && c == '*'))) {
      out += ' ';
    }
    out += c;
  }
  return out;
}

// The identifier stem of a serial or method: letters and digits kept (upper case), every other
// byte '_'. Two serials that differ only in case or punctuation get the same stem; including both
// headers is then a compile error (redefinition), never a silent mix-up.
std::string IdentifierStem(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (c >= 'a' && c <= 'z') {
      out += static_cast<char>(c - 'a' + 'A');
    } else if ((c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9')) {
      out += static_cast<char>(c);
    } else {
      out += '_';
    }
  }
  return out.empty() ? "_" : out;
}

std::string LowerCase(std::string s) {
  for (char& c : s) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return s;
}

// A C double literal (full precision); the caller has checked that v is a finite number.
std::string CDouble(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

// Reads `n` numbers of a JSON array into *out; false when the shape is wrong or any is null.
bool Numbers(const json& v, size_t n, std::vector<double>* out) {
  out->clear();
  if (!v.is_array() || v.size() != n) return false;
  for (const json& x : v) {
    if (!x.is_number()) return false;
    out->push_back(x.get<double>());
  }
  return true;
}

// Writes a C99/C++ header. Constants are `static const` (internal linkage in both languages) or
// macros, all named PREFIX_...; functions prefix_... (lower case).
class HeaderWriter {
 public:
  HeaderWriter(const ExportContext& context, const std::string& method)
      : macro_("CALIBD_" + IdentifierStem(context.device) + "_" + IdentifierStem(method) + "_"),
        func_(LowerCase(macro_)) {}

  const std::string& macro() const { return macro_; }
  const std::string& func() const { return func_; }
  std::ostringstream& out() { return h_; }

  void Define(const std::string& name, const std::string& value, const std::string& comment) {
    h_ << "#define " << macro_ << name << " " << value;
    if (!comment.empty()) h_ << "  /* " << CComment(comment) << " */";
    h_ << "\n";
  }
  void Array1(const std::string& name, const std::vector<double>& v, const std::string& comment) {
    if (!comment.empty()) h_ << "/* " << CComment(comment) << " */\n";
    h_ << "static const double " << macro_ << name << "[" << v.size() << "] = {";
    for (size_t i = 0; i < v.size(); ++i) h_ << (i ? ", " : "") << CDouble(v[i]);
    h_ << "};\n";
  }
  void Array2(const std::string& name, const std::vector<std::vector<double>>& rows, size_t cols,
              const std::string& comment) {
    if (!comment.empty()) h_ << "/* " << CComment(comment) << " */\n";
    h_ << "static const double " << macro_ << name << "[" << rows.size() << "][" << cols
       << "] = {\n";
    for (const auto& row : rows) {
      h_ << "    {";
      for (size_t c = 0; c < row.size(); ++c) h_ << (c ? ", " : "") << CDouble(row[c]);
      h_ << "},\n";
    }
    h_ << "};\n";
  }
  void Names(const std::string& name, const std::vector<std::string>& names) {
    h_ << "static const char* const " << macro_ << name << "[" << names.size() << "] = {";
    for (size_t i = 0; i < names.size(); ++i) h_ << (i ? ", " : "") << CString(names[i]);
    h_ << "};\n";
  }

 private:
  std::string macro_, func_;
  std::ostringstream h_;
};

// Per-entry standard deviations: the array when every entry is defined, else a comment naming
// the entries whose σ is undefined (never a made-up 0).
void StdArray1(HeaderWriter* w, const std::string& name, const json& items, const char* key,
               const std::vector<std::string>& names, const std::string& comment) {
  std::vector<double> values;
  std::string undefined;
  for (size_t i = 0; i < names.size(); ++i) {
    const json& v = items.is_array() && i < items.size() ? Get(items[i], key) : json();
    if (v.is_number()) {
      values.push_back(v.get<double>());
    } else {
      undefined += (undefined.empty() ? "" : ", ") + names[i];
    }
  }
  if (undefined.empty()) {
    w->Array1(name, values, comment);
  } else {
    w->out() << "/* " << w->macro() << name << " is not written: " << CComment(key)
             << " is undefined for " << CComment(undefined) << " (see format=json). */\n";
  }
}

Status PcaHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& sensors = Get(params, "sensors");
  if (!sensors.is_array() || sensors.empty()) {
    return Status::Internal("stored pca result has no parameters.sensors");
  }
  const size_t m = sensors.size();
  const json& dim = Get(params, "dimension");
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
    names.push_back(Get(s, "name").is_string() ? s["name"].get<std::string>() : "");
    std::vector<double> b;
    if (!Numbers(Get(s, "sensitivity"), d, &sensitivity[i]) ||
        !Numbers(Get(s, "axis"), d, &axis[i]) || !Get(s, "scale").is_number()) {
      return Status::NotDeterminable("the pca result of sensor '" + names.back() +
                                     "' has undefined parameters: no C header can be written");
    }
    scale[i] = s["scale"].get<double>();
    if (Get(s, "bias").is_number()) bias[i] = s["bias"].get<double>();
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
      Get(params, "magnitude_known").is_boolean() && params["magnitude_known"].get<bool>();
  const std::string frame =
      Get(params, "frame").is_string() ? params["frame"].get<std::string>() : "";
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
  const json& usens = Get(unc, "sensors");
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

Status ArrayHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& positions = Get(params, "positions");
  if (!positions.is_array() || positions.empty()) {
    return Status::Internal("stored array result has no parameters.positions");
  }
  const size_t k = positions.size();
  std::vector<std::string> names;
  std::vector<std::vector<double>> position(k), offset(k), stds;
  for (size_t i = 0; i < k; ++i) {
    const json& p = positions[i];
    names.push_back(Get(p, "name").is_string() ? p["name"].get<std::string>() : "");
    if (!Numbers(Get(p, "position"), 3, &position[i]) ||
        !Numbers(Get(p, "offset"), 3, &offset[i])) {
      return Status::NotDeterminable("the array result of triad '" + names.back() +
                                     "' has an undefined position: no C header can be written");
    }
  }
  w->Define("TRIADS", std::to_string(k), "accelerometer triads K");
  w->Define("REFERENCE",
            std::to_string(
                Get(params, "reference").is_number_integer() ? params["reference"].get<int>() : 0),
            "index of the reference triad, held at its nominal position");
  w->Names("NAMES", names);
  w->Array2("POSITION", position, 3, "r_k: triad positions, metres, nominal geometry frame");
  w->Array2("OFFSET", offset, 3, "offset from the nominal position, metres");
  const json& upos = Get(unc, "positions");
  bool all = upos.is_array() && upos.size() == k;
  for (size_t i = 0; all && i < k; ++i) {
    std::vector<double> s;
    all = Numbers(Get(upos[i], "std"), 3, &s);
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

// imu (and any result with parameters.imus): per IMU a = MATRIX (y - BIAS) for both triads.
// `sub` prefixes the names that the array header has too (NAMES, and IMUS for symmetry).
Status ImuHeader(const json& params, const json& unc, const std::string& sub, HeaderWriter* w) {
  const json& imus = Get(params, "imus");
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
    names.push_back(Get(imus[i], "name").is_string() ? imus[i]["name"].get<std::string>() : "");
    for (int t = 0; t < 2; ++t) {
      const json& p = Get(imus[i], sensors[t]);
      std::vector<double> b, row;
      std::vector<std::vector<double>> m;
      bool ok =
          Numbers(Get(p, "bias"), 3, &b) && Get(p, "matrix").is_array() && p["matrix"].size() == 3;
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
  const json& uimus = Get(unc, "imus");
  for (int t = 0; t < 2; ++t) {
    for (const char* key : {"bias_std", "scale_std"}) {
      std::vector<std::vector<double>> rows;
      bool all = uimus.is_array() && uimus.size() == n;
      for (size_t i = 0; all && i < n; ++i) {
        std::vector<double> v;
        all = Numbers(Get(Get(uimus[i], sensors[t]), key), 3, &v);
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

// noise: per channel one macro per figure; a figure the log could not show is not defined (a
// comment says so), never 0.
Status NoiseHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& channels = Get(params, "channels");
  if (!channels.is_array() || channels.empty()) {
    return Status::Internal("stored noise result has no channels");
  }
  const json& uch = Get(unc, "channels");
  std::vector<std::string> names;
  for (const json& c : channels) {
    names.push_back(Get(c, "name").is_string() ? c["name"].get<std::string>() : "");
  }
  w->Define("CHANNELS", std::to_string(names.size()), "");
  w->Names("NAMES", names);
  for (size_t i = 0; i < channels.size(); ++i) {
    const json& c = channels[i];
    const json& u = uch.is_array() && i < uch.size() ? uch[i] : json();
    const std::string unit = Get(c, "unit").is_string() ? c["unit"].get<std::string>() : "unit";
    const std::string id = IdentifierStem(names[i]) + "_";
    struct Term {
      const char* key;
      const char* std_key;
      const char* name;
      std::string unit;
    } terms[] = {{"white_noise", "white_noise_std", "WHITE_NOISE", unit + "/sqrt(Hz)"},
                 {"bias_instability", "bias_instability_std", "BIAS_INSTABILITY", unit},
                 {"bias_instability_tau", nullptr, "BIAS_INSTABILITY_TAU", "s"},
                 {"random_walk", "random_walk_std", "RANDOM_WALK", unit + "/s/sqrt(Hz)"}};
    w->out() << "/* channel " << CComment(names[i]) << " (" << CComment(unit) << ") */\n";
    for (const Term& t : terms) {
      const json& v = Get(c, t.key);
      if (!v.is_number()) {
        w->out() << "/* " << w->macro() << id << t.name
                 << " is not defined: the log is too short to show it */\n";
        continue;
      }
      w->Define(id + t.name, CDouble(v.get<double>()), t.unit);
      if (t.std_key != nullptr && Get(u, t.std_key).is_number()) {
        w->Define(id + t.name + "_STD", CDouble(u[t.std_key].get<double>()), "1 sigma");
      }
    }
  }
  return Status::Ok();
}

// The equation, stated in the header's comment, per method.
const char* ModelComment(const std::string& method) {
  if (method == "pca") {
    return " * Model (pca): the raw reading of sensor i is r_i = a_i . v + b_i, for the field v\n"
           " * (DIMENSION components), a_i = SCALE_i * AXIS_i the sensitivity vector, b_i the "
           "bias.\n"
           " * The calibrated field from one raw reading of all SENSORS sensors is the least-\n"
           " * squares inverse v = (A^T A)^-1 A^T (r - b), A the SENSORS x DIMENSION matrix of\n"
           " * rows a_i: INVERSE below, applied by *_pca_apply().\n";
  }
  if (method == "array") {
    return " * Model (array): accelerometer triad k at position r_k reads\n"
           " * y_a,k = s + (Omega(w)^2 + Omega(w'))r_k, the gyroscopes y_g = w (s the specific\n"
           " * force at the origin, w the angular rate, Omega(x) the cross-product matrix).\n"
           " * The parameters are the positions POSITION (data, nothing to apply per reading).\n"
           " * With model full, per IMU a = ACCEL_MATRIX (y_a - ACCEL_BIAS),\n"
           " * omega = GYRO_MATRIX (y_g - GYRO_BIAS), applied by *_array_apply().\n";
  }
  if (method == "imu") {
    return " * Model (imu, the imu_tk convention): a = T_a K_a (y_a - b_a),\n"
           " * omega = T_g K_g (y_g - b_g); y raw readings, b biases (reading units), K diagonal\n"
           " * scales (SI per reading unit), T_a upper triangular (the body frame is the\n"
           " * accelerometer's), T_g the gyroscope's misalignment to it. MATRIX = T K, applied by\n"
           " * *_imu_apply().\n";
  }
  return " * Model (noise, IEEE Std 952): per channel the Allan variance\n"
         " * sigma^2(tau) = N^2/tau + (0.664 B)^2 + K^2 tau/3: N = WHITE_NOISE (noise density,\n"
         " * Kalibr's noise_density), B = BIAS_INSTABILITY, K = RANDOM_WALK (Kalibr's\n"
         " * random_walk). Figures as data; nothing to apply per reading.\n";
}

}  // namespace

Status ResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  const std::string method =
      Get(result, "method").is_string() ? result["method"].get<std::string>() : "";
  if (method != "pca" && method != "array" && method != "imu" && method != "noise") {
    return Status::Internal("stored result has an unknown method");
  }
  const json& params = Get(result, "parameters");
  const json& unc = Get(result, "uncertainty");
  HeaderWriter body(context, method);
  Status s = method == "pca"     ? PcaHeader(params, unc, &body)
             : method == "array" ? ArrayHeader(params, unc, &body)
             : method == "imu"   ? ImuHeader(params, unc, "", &body)
                                 : NoiseHeader(params, unc, &body);
  if (!s.ok()) return s;
  // An array result of the full model carries per-IMU intrinsics as well.
  if (method == "array" && Get(params, "imus").is_array()) {
    s = ImuHeader(params, unc, "IMU_", &body);
    if (!s.ok()) return s;
  }
  if (method == "noise" && Get(Get(result, "diagnostics"), "rate").is_number()) {
    body.Define("RATE", CDouble(result["diagnostics"]["rate"].get<double>()), "Hz");
  }
  const std::string guard = body.macro() + "JOB_" + std::to_string(context.job_id) + "_H_";
  std::ostringstream h;
  h << "/* Generated by calibd: " << CComment(method) << " calibration of device '"
    << CComment(context.device) << "', job " << context.job_id << ", finished "
    << CComment(context.finished_at) << ".\n"
    << " * Fetch again from /api/v1/devices/{serial}/calibration?method=" << CComment(method)
    << "&format=h; do not edit.\n"
    << " * Valid C99 and C++; every name starts with " << body.macro() << " or " << body.func()
    << ",\n"
    << " * so headers of several devices and methods can be included in one program.\n"
    << " *\n"
    << ModelComment(method) << " */\n"
    << "#ifndef " << guard << "\n#define " << guard << "\n\n";
  HeaderWriter head(context, method);
  head.Define("JOB_ID", std::to_string(context.job_id) + "LL", "");
  head.Define("DEVICE", CString(context.device), "");
  head.Define("FINISHED_AT", CString(context.finished_at), "UTC");
  h << head.out().str() << body.out().str() << "\n#endif /* " << guard << " */\n";
  *out = h.str();
  return Status::Ok();
}

}  // namespace calibd::server
