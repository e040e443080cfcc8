// Exports of a noise result (methods/noise/noise_method.h): CSV, Kalibr's imu.yaml and the C
// header. Each reads the stored result once into results::NoiseResult; a result that does not read
// is kInternal with the reader's message.
#include <cmath>
#include <sstream>
#include <string>

#include "methods/export_util.h"
#include "methods/noise/noise_method.h"
#include "methods/noise/noise_result.h"

namespace calibd::server {

namespace {

// The equation, stated in the header's comment.
constexpr const char* kNoiseModel =
    " * Model (noise, IEEE Std 952): per channel the Allan variance\n"
    " * sigma^2(tau) = N^2/tau + (0.664 B)^2 + K^2 tau/3: N = WHITE_NOISE (noise density,\n"
    " * Kalibr's noise_density), B = BIAS_INSTABILITY, K = RANDOM_WALK (Kalibr's\n"
    " * random_walk). Figures as data; nothing to apply per reading.\n";

// The stored result, typed; kInternal naming the first problem when it does not read.
Status ReadResult(const json& result, results::NoiseResult* out) {
  Status s = results::FromJson(result, out);
  if (!s.ok()) return UnreadableStoredResult(s);
  if (!out->envelope.usable) {
    return Status::Internal("stored noise result is the partial diagnostics of a failed run");
  }
  return Status::Ok();
}

// A CSV cell: "" for an undefined value (null in JSON), never 0.
std::string Cell(double v) { return CsvNumber(results::Num(v)); }

// noise: per channel one macro per figure; a figure the log could not show is not defined (a
// comment says so), never 0.
Status NoiseHeader(const results::NoiseResult& r, HeaderWriter* w) {
  if (r.channels.empty()) return Status::Internal("stored noise result has no channels");
  std::vector<std::string> names;
  for (const auto& c : r.channels) names.push_back(c.name);
  w->Define("CHANNELS", std::to_string(names.size()), "");
  w->Names("NAMES", names);
  for (size_t i = 0; i < r.channels.size(); ++i) {
    const results::NoiseChannelParameters& c = r.channels[i];
    const results::NoiseChannelUncertainty& u = r.channel_stds[i];
    const std::string id = IdentifierStem(c.name) + "_";
    struct Term {
      double value;
      double std;  // NaN: no _STD macro (undefined, or the term has none)
      const char* name;
      std::string unit;
    } terms[] = {{c.white_noise, u.white_noise_std, "WHITE_NOISE", c.unit + "/sqrt(Hz)"},
                 {c.bias_instability, u.bias_instability_std, "BIAS_INSTABILITY", c.unit},
                 {c.bias_instability_tau, std::nan(""), "BIAS_INSTABILITY_TAU", "s"},
                 {c.random_walk, u.random_walk_std, "RANDOM_WALK", c.unit + "/s/sqrt(Hz)"}};
    w->out() << "/* channel " << CComment(c.name) << " (" << CComment(c.unit) << ") */\n";
    for (const Term& t : terms) {
      if (!std::isfinite(t.value)) {
        w->out() << "/* " << w->macro() << id << t.name
                 << " is not defined: the log is too short to show it */\n";
        continue;
      }
      w->Define(id + t.name, CDouble(t.value), t.unit);
      if (std::isfinite(t.std)) w->Define(id + t.name + "_STD", CDouble(t.std), "1 sigma");
    }
  }
  return Status::Ok();
}

}  // namespace

Status NoiseResultToCsv(const json& result, std::string* out) {
  results::NoiseResult r;
  Status s = ReadResult(result, &r);
  if (!s.ok()) return s;
  std::ostringstream csv;
  csv << "name,unit,white_noise,white_noise_std,bias_instability,bias_instability_std,"
         "bias_instability_tau,random_walk,random_walk_std\n";
  for (size_t i = 0; i < r.channels.size(); ++i) {
    const results::NoiseChannelParameters& c = r.channels[i];
    const results::NoiseChannelUncertainty& u = r.channel_stds[i];
    // A term the log could not show stays empty (null in JSON), never 0.
    csv << CsvField(c.name) << "," << CsvField(c.unit) << "," << Cell(c.white_noise) << ","
        << Cell(u.white_noise_std) << "," << Cell(c.bias_instability) << ","
        << Cell(u.bias_instability_std) << "," << Cell(c.bias_instability_tau) << ","
        << Cell(c.random_walk) << "," << Cell(u.random_walk_std) << "\n";
  }
  *out = csv.str();
  return Status::Ok();
}

Status NoiseResultToKalibrYaml(const json& result, const ExportContext& context, std::string* out) {
  results::NoiseResult r;
  Status s = ReadResult(result, &r);
  if (!s.ok()) return s;
  // Per sensor type the largest of its axes (Kalibr takes one figure for all three; the largest
  // keeps a filter from trusting the sensor more than its worst axis allows).
  struct Worst {
    double value = -1;
    std::string axis;
    std::vector<std::string> missing;
  };
  Worst worst[2][2];  // [accelerometer, gyroscope][white_noise, random_walk]
  bool seen[2] = {false, false};
  for (const results::NoiseChannelParameters& c : r.channels) {
    if (c.name.empty() || (c.name[0] != 'a' && c.name[0] != 'g')) continue;
    const int type = c.name[0] == 'a' ? 0 : 1;
    seen[type] = true;
    const double values[2] = {c.white_noise, c.random_walk};
    for (int k = 0; k < 2; ++k) {
      if (!std::isfinite(values[k])) {
        worst[type][k].missing.push_back(c.name);
      } else if (values[k] > worst[type][k].value) {
        worst[type][k].value = values[k];
        worst[type][k].axis = c.name;
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
      std::string list;
      for (const auto& m : w.missing) list += (list.empty() ? "" : ", ") + m;
      const std::string term = k == 0 ? "white noise" : "random walk";
      if (w.value < 0) {  // no axis shows it: there is nothing to write
        return Status::NotDeterminable(
            "the log does not show the " + term + " of " + list +
            " (see the result's warnings for how long a log would): Kalibr's " + type_names[type] +
            "_" + keys[k] + " cannot be written");
      }
      // Some axes show it: the largest of those is written, and the file says which axes the
      // log was too short for (a device's export never fails because one axis is short).
      y << type_names[type] << "_" << keys[k] << ": " << Cell(w.value) << "  # " << units[type][k]
        << ", " << w.axis;
      if (!w.missing.empty()) {
        y << "; the log does not show the " << term << " of " << CommentSafe(list)
          << ": the largest of the other axes";
      }
      y << "\n";
    }
  }
  if (!std::isfinite(r.diagnostics.rate)) {
    return Status::NotDeterminable(
        "the noise result has no sample rate (diagnostics.rate is null): Kalibr's update_rate "
        "cannot be written");
  }
  y << "rostopic: /imu0\n"
    << "update_rate: " << MeasuredRate(r.diagnostics.rate) << "  # Hz, measured\n";
  *out = y.str();
  return Status::Ok();
}

Status NoiseResultToHeader(const json& result, const ExportContext& context, std::string* out) {
  results::NoiseResult r;
  Status s = ReadResult(result, &r);
  if (!s.ok()) return s;
  return WriteCHeader(
      result, context, "noise", kNoiseModel,
      [&](const json&, const json&, HeaderWriter* w) {
        Status body = NoiseHeader(r, w);
        if (body.ok() && std::isfinite(r.diagnostics.rate)) {
          w->Define("RATE", MeasuredRate(r.diagnostics.rate), "Hz, measured");
        }
        return body;
      },
      out);
}

}  // namespace calibd::server
