// Exports of a noise result (server/noise_method.h): CSV, Kalibr's imu.yaml and the C header.
#include <sstream>
#include <string>

#include "server/export_util.h"
#include "server/noise_method.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kNoiseModel =
    " * Model (noise, IEEE Std 952): per channel the Allan variance\n"
    " * sigma^2(tau) = N^2/tau + (0.664 B)^2 + K^2 tau/3: N = WHITE_NOISE (noise density,\n"
    " * Kalibr's noise_density), B = BIAS_INSTABILITY, K = RANDOM_WALK (Kalibr's\n"
    " * random_walk). Figures as data; nothing to apply per reading.\n";

// noise: per channel one macro per figure; a figure the log could not show is not defined (a
// comment says so), never 0.
Status NoiseHeader(const json& params, const json& unc, HeaderWriter* w) {
  const json& channels = JsonAt(params, "channels");
  if (!channels.is_array() || channels.empty()) {
    return Status::Internal("stored noise result has no channels");
  }
  const json& uch = JsonAt(unc, "channels");
  std::vector<std::string> names;
  for (const json& c : channels) {
    names.push_back(JsonAt(c, "name").is_string() ? c["name"].get<std::string>() : "");
  }
  w->Define("CHANNELS", std::to_string(names.size()), "");
  w->Names("NAMES", names);
  for (size_t i = 0; i < channels.size(); ++i) {
    const json& c = channels[i];
    const json& u = uch.is_array() && i < uch.size() ? uch[i] : json();
    const std::string unit = JsonAt(c, "unit").is_string() ? c["unit"].get<std::string>() : "unit";
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
      const json& v = JsonAt(c, t.key);
      if (!v.is_number()) {
        w->out() << "/* " << w->macro() << id << t.name
                 << " is not defined: the log is too short to show it */\n";
        continue;
      }
      w->Define(id + t.name, CDouble(v.get<double>()), t.unit);
      if (t.std_key != nullptr && JsonAt(u, t.std_key).is_number()) {
        w->Define(id + t.name + "_STD", CDouble(u[t.std_key].get<double>()), "1 sigma");
      }
    }
  }
  return Status::Ok();
}

}  // namespace

Status NoiseResultToCsv(const json& result, std::string* out) {
  std::ostringstream csv;
  const json& params = JsonAt(result, "parameters");
  const json& unc = JsonAt(result, "uncertainty");
  const json& channels = JsonAt(params, "channels");
  if (!channels.is_array()) return Status::Internal("stored noise result has no channels");
  const json& uch = JsonAt(unc, "channels");
  csv << "name,unit,white_noise,white_noise_std,bias_instability,bias_instability_std,"
         "bias_instability_tau,random_walk,random_walk_std\n";
  for (size_t i = 0; i < channels.size(); ++i) {
    const json& c = channels[i];
    const json& u = uch.is_array() && i < uch.size() ? uch[i] : json();
    const json& name = JsonAt(c, "name");
    const json& unit = JsonAt(c, "unit");
    // A term the log could not show stays empty (null in JSON), never 0.
    csv << CsvField(name.is_string() ? name.get<std::string>() : "") << ","
        << CsvField(unit.is_string() ? unit.get<std::string>() : "") << ","
        << CsvNumber(JsonAt(c, "white_noise")) << "," << CsvNumber(JsonAt(u, "white_noise_std"))
        << "," << CsvNumber(JsonAt(c, "bias_instability")) << ","
        << CsvNumber(JsonAt(u, "bias_instability_std")) << ","
        << CsvNumber(JsonAt(c, "bias_instability_tau")) << ","
        << CsvNumber(JsonAt(c, "random_walk")) << "," << CsvNumber(JsonAt(u, "random_walk_std"))
        << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status NoiseResultToKalibrYaml(const json& result, const ExportContext& context, std::string* out) {
  const json& channels = JsonAt(JsonAt(result, "parameters"), "channels");
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
    const std::string name = JsonAt(c, "name").is_string() ? c["name"].get<std::string>() : "";
    if (name.empty() || (name[0] != 'a' && name[0] != 'g')) continue;
    const int type = name[0] == 'a' ? 0 : 1;
    seen[type] = true;
    const char* keys[2] = {"white_noise", "random_walk"};
    for (int k = 0; k < 2; ++k) {
      const json& v = JsonAt(c, keys[k]);
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
      y << type_names[type] << "_" << keys[k] << ": " << CsvNumber(json(w.value)) << "  # "
        << units[type][k] << ", " << w.axis << "\n";
    }
  }
  const json& rate = JsonAt(JsonAt(result, "diagnostics"), "rate");
  y << "rostopic: /imu0\n"
    << "update_rate: " << CsvNumber(rate) << "  # Hz\n";
  *out = y.str();
  return Status::Ok();
}

Status NoiseResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  return WriteCHeader(
      result, context, "noise", kNoiseModel,
      [&](const json& params, const json& unc, HeaderWriter* w) {
        Status s = NoiseHeader(params, unc, w);
        const json& rate = JsonAt(JsonAt(result, "diagnostics"), "rate");
        if (s.ok() && rate.is_number()) w->Define("RATE", CDouble(rate.get<double>()), "Hz");
        return s;
      },
      out);
}

}  // namespace calibd::server
