#include "server/exports.h"

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

std::string CNum(const json& v) {
  if (!v.is_number()) return "0.0 /* undefined */";
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v.get<double>());
  std::string s = buf;
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
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
    if (c == '"' || c == '\\') {
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

Status ResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  std::ostringstream h;
  const std::string method =
      Get(result, "method").is_string() ? result["method"].get<std::string>() : "";
  const json& params = Get(result, "parameters");
  const json& unc = Get(result, "uncertainty");
  h << "// Generated by calibd: " << CommentSafe(method) << " calibration of device '"
    << CommentSafe(context.device) << "', job " << context.job_id << ", finished "
    << CommentSafe(context.finished_at) << ".\n"
    << "// Do not edit: fetch again from /api/v1/devices/{serial}/calibration?format=h\n"
    << "#pragma once\n\nnamespace calibd_calibration {\n\n"
    << "constexpr long long kJobId = " << context.job_id << ";\n"
    << "constexpr const char* kDevice = " << CString(context.device) << ";\n"
    << "constexpr const char* kFinishedAt = " << CString(context.finished_at) << ";\n";
  auto array1 = [&h](const char* name, const std::vector<std::string>& values) {
    h << "constexpr double " << name << "[" << values.size() << "] = {";
    for (size_t i = 0; i < values.size(); ++i) h << (i ? ", " : "") << values[i];
    h << "};\n";
  };
  auto names = [&h](const std::vector<std::string>& values) {
    h << "constexpr const char* kNames[" << values.size() << "] = {";
    for (size_t i = 0; i < values.size(); ++i) h << (i ? ", " : "") << CString(values[i]);
    h << "};\n";
  };
  if (method == "pca") {
    const json& sensors = Get(params, "sensors");
    if (!sensors.is_array() || sensors.empty()) {
      return Status::Internal("stored pca result has no parameters.sensors");
    }
    const size_t m = sensors.size();
    const size_t d = Get(params, "dimension").is_number() ? params["dimension"].get<size_t>() : 3;
    const json& usens = Get(unc, "sensors");
    std::vector<std::string> sensor_names, scale, scale_std, bias, bias_std;
    for (size_t i = 0; i < m; ++i) {
      const json& s = sensors[i];
      const json& u = usens.is_array() && i < usens.size() ? usens[i] : json();
      sensor_names.push_back(Get(s, "name").is_string() ? s["name"].get<std::string>() : "");
      scale.push_back(CNum(Get(s, "scale")));
      scale_std.push_back(CNum(Get(u, "scale_std")));
      bias.push_back(CNum(Get(s, "bias")));
      bias_std.push_back(CNum(Get(u, "bias_std")));
    }
    h << "constexpr int kSensors = " << m << ";\nconstexpr int kDimension = " << d << ";\n"
      << "constexpr bool kMagnitudeKnown = "
      << (Get(params, "magnitude_known").is_boolean() && params["magnitude_known"].get<bool>()
              ? "true"
              : "false")
      << ";\n";
    names(sensor_names);
    for (const char* key : {"sensitivity", "axis"}) {
      h << "// " << key << " vectors, one row per sensor ("
        << CommentSafe(Get(params, "frame").is_string() ? params["frame"].get<std::string>() : "")
        << " frame)\n";
      h << "constexpr double k" << (key[0] == 's' ? "Sensitivity" : "Axis") << "[" << m << "][" << d
        << "] = {\n";
      for (size_t i = 0; i < m; ++i) {
        const json& v = Get(sensors[i], key);
        h << "    {";
        for (size_t k = 0; k < d; ++k) {
          h << (k ? ", " : "") << (v.is_array() && k < v.size() ? CNum(v[k]) : CNum(json()));
        }
        h << "},\n";
      }
      h << "};\n";
    }
    array1("kScale", scale);
    array1("kScaleStd", scale_std);
    array1("kBias", bias);
    array1("kBiasStd", bias_std);
  } else if (method == "array") {
    const json& positions = Get(params, "positions");
    if (!positions.is_array() || positions.empty()) {
      return Status::Internal("stored array result has no parameters.positions");
    }
    const size_t k = positions.size();
    const json& upos = Get(unc, "positions");
    std::vector<std::string> triad_names;
    for (const json& p : positions) {
      triad_names.push_back(Get(p, "name").is_string() ? p["name"].get<std::string>() : "");
    }
    h << "constexpr int kTriads = " << k << ";\nconstexpr int kReference = "
      << (Get(params, "reference").is_number_integer() ? params["reference"].get<int>() : 0)
      << ";\n";
    names(triad_names);
    auto matrix = [&](const char* name, const char* comment, auto get) {
      h << "// " << comment << "\nconstexpr double " << name << "[" << k << "][3] = {\n";
      for (size_t i = 0; i < k; ++i) {
        const json& v = get(i);
        h << "    {";
        for (size_t c = 0; c < 3; ++c) {
          h << (c ? ", " : "") << (v.is_array() && c < v.size() ? CNum(v[c]) : CNum(json()));
        }
        h << "},\n";
      }
      h << "};\n";
    };
    matrix("kPosition", "triad positions, metres, nominal geometry frame",
           [&](size_t i) -> const json& { return Get(positions[i], "position"); });
    matrix("kOffset", "offset from the nominal position, metres",
           [&](size_t i) -> const json& { return Get(positions[i], "offset"); });
    matrix("kPositionStd", "one standard deviation (Cramer-Rao bound), metres",
           [&](size_t i) -> const json& {
             static const json kNull;
             return upos.is_array() && i < upos.size() ? Get(upos[i], "std") : kNull;
           });
  } else {
    return Status::Internal("stored result has an unknown method");
  }
  h << "\n}  // namespace calibd_calibration\n";
  *out = h.str();
  return Status::Ok();
}

}  // namespace calibd::server
