// From a sensor log's streams to the recording the methods read (formats/log_assembly.h).
#include "formats/log_assembly.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace calibd::server {

namespace {

using nlohmann::json;

Status StreamsError(const std::string& path, const std::string& what) {
  return Status::InvalidInput("config '" + path + "' " + what).WithField("streams");
}

Status ReadName(const json& object, const char* key, const std::string& path, std::string* out) {
  const auto it = object.find(key);
  if (it == object.end() || it->is_null()) return Status::Ok();
  if (!it->is_string() || it->get_ref<const std::string&>().empty()) {
    return StreamsError(path + "." + key, "must be a stream name such as \"sensor_accel:0\"");
  }
  *out = it->get<std::string>();
  return Status::Ok();
}

// The median of the positive steps of t (ns); 0 with fewer than two samples.
int64_t MedianStep(const std::vector<int64_t>& t) {
  std::vector<int64_t> steps;
  steps.reserve(t.size());
  for (size_t i = 1; i < t.size(); ++i) {
    if (t[i] > t[i - 1]) steps.push_back(t[i] - t[i - 1]);
  }
  if (steps.empty()) return 0;
  auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  return *mid;
}

std::string StreamList(const SensorLog& log) {
  std::string list;
  for (const SensorStream& s : log.streams) {
    if (!list.empty()) list += ", ";
    list += s.Name() + " (" + StreamKindName(s.kind) + ")";
  }
  return list.empty() ? "none" : list;
}

const SensorStream* FindStream(const SensorLog& log, const std::string& name, StreamKind kind) {
  for (const SensorStream& s : log.streams) {
    if (s.kind == kind && s.Name() == name) return &s;
  }
  return nullptr;
}

// The default pairing: each accelerometer with the gyroscope of its own topic and instance (one
// message carries both: DataFlash IMU, ROS Imu), else of its device id (ULog), else of its
// instance on the matching topic ("sensor_accel:1" and "sensor_gyro:1").
std::vector<LogStreamSelection::Imu> DefaultImus(const SensorLog& log) {
  std::vector<const SensorStream*> accels, gyros;
  for (const SensorStream& s : log.streams) {
    if (s.kind == StreamKind::kAccel) accels.push_back(&s);
    if (s.kind == StreamKind::kGyro) gyros.push_back(&s);
  }
  std::vector<bool> used(gyros.size(), false);
  auto take = [&](auto&& match) -> const SensorStream* {
    for (size_t j = 0; j < gyros.size(); ++j) {
      if (!used[j] && match(*gyros[j])) {
        used[j] = true;
        return gyros[j];
      }
    }
    return nullptr;
  };
  auto temperature_of = [&](const SensorStream* s) -> std::string {
    if (s == nullptr) return "";
    const SensorStream* t = FindStream(log, s->Name(), StreamKind::kTemperature);
    return t == nullptr ? "" : t->Name();
  };
  std::vector<LogStreamSelection::Imu> imus;
  for (const SensorStream* a : accels) {
    const SensorStream* g = take([&](const SensorStream& s) { return s.Name() == a->Name(); });
    if (g == nullptr && a->device_id >= 0) {
      g = take([&](const SensorStream& s) { return s.device_id == a->device_id; });
    }
    if (g == nullptr) {
      std::string topic = a->topic;
      const size_t at = topic.find("accel");
      if (at != std::string::npos) topic.replace(at, 5, "gyro");
      g = take([&](const SensorStream& s) {
        return s.topic == topic && s.instance == a->instance && s.device_id < 0;
      });
    }
    LogStreamSelection::Imu imu{a->Name(), g == nullptr ? "" : g->Name(), temperature_of(a)};
    if (imu.temp.empty()) imu.temp = temperature_of(g);
    imus.push_back(imu);
  }
  for (size_t j = 0; j < gyros.size(); ++j) {
    if (!used[j]) imus.push_back({"", gyros[j]->Name(), temperature_of(gyros[j])});
  }
  return imus;
}

// The samples of `s` whose time increases, as indices; *dropped counts the others.
std::vector<size_t> IncreasingSamples(const SensorStream& s, int64_t* dropped) {
  std::vector<size_t> keep;
  keep.reserve(s.t_ns.size());
  for (size_t i = 0; i < s.t_ns.size(); ++i) {
    if (keep.empty() || s.t_ns[i] > s.t_ns[keep.back()]) keep.push_back(i);
  }
  *dropped = static_cast<int64_t>(s.t_ns.size() - keep.size());
  return keep;
}

// Linear interpolation of `s` (dimension d, increasing samples `idx`) at time t: writes d values.
// `cursor` walks forward with increasing t. Outside s's span the end values are held.
void Interpolate(const SensorStream& s, const std::vector<size_t>& idx, int64_t t, size_t* cursor,
                 double* out) {
  const int d = StreamDimension(s.kind);
  while (*cursor + 1 < idx.size() && s.t_ns[idx[*cursor + 1]] <= t) ++*cursor;
  const size_t i0 = idx[*cursor];
  if (*cursor + 1 >= idx.size() || t <= s.t_ns[i0]) {
    for (int k = 0; k < d; ++k) out[k] = s.values[i0 * d + k];
    return;
  }
  const size_t i1 = idx[*cursor + 1];
  const double w =
      static_cast<double>(t - s.t_ns[i0]) / static_cast<double>(s.t_ns[i1] - s.t_ns[i0]);
  for (int k = 0; k < d; ++k) {
    out[k] = (1 - w) * s.values[i0 * d + k] + w * s.values[i1 * d + k];
  }
}

// Writes `s`'s values at the times t into columns [column, column + dim) of *m: sample by sample
// when s has exactly those times, else interpolated (Interpolate), and then s's name is appended
// to *resampled.
void FillColumns(const SensorStream& s, const std::vector<int64_t>& t, Eigen::MatrixXd* m,
                 int column, json* resampled) {
  int64_t unused = 0;
  const std::vector<size_t> idx = IncreasingSamples(s, &unused);
  const size_t n = t.size();
  bool same = idx.size() == n;
  for (size_t i = 0; same && i < n; ++i) same = s.t_ns[idx[i]] == t[i];
  if (!same) resampled->push_back(s.Name());
  const int dim = StreamDimension(s.kind);
  size_t cursor = 0;
  double v[3];
  for (size_t i = 0; i < n; ++i) {
    if (same) {
      for (int j = 0; j < dim; ++j) v[j] = s.values[idx[i] * dim + j];
    } else {
      Interpolate(s, idx, t[i], &cursor, v);
    }
    for (int j = 0; j < dim; ++j) (*m)(static_cast<Eigen::Index>(i), column + j) = v[j];
  }
}

struct ImuStreams {
  const SensorStream* accel = nullptr;
  const SensorStream* gyro = nullptr;
  const SensorStream* temp = nullptr;
  const SensorStream* base() const { return gyro != nullptr ? gyro : accel; }
};

Status Resolve(const SensorLog& log, const LogStreamSelection::Imu& imu, size_t k,
               ImuStreams* out) {
  const std::string path = "streams.imus[" + std::to_string(k) + "]";
  auto find = [&](const std::string& name, StreamKind kind, const char* key,
                  const SensorStream** s) -> Status {
    if (name.empty()) return Status::Ok();
    *s = FindStream(log, name, kind);
    if (*s != nullptr) return Status::Ok();
    return StreamsError(path + "." + key, "names '" + name + "', which this " + log.format +
                                              " log has no " + StreamKindName(kind) +
                                              " stream of; it has: " + StreamList(log));
  };
  Status s = find(imu.accel, StreamKind::kAccel, "accel", &out->accel);
  if (s.ok()) s = find(imu.gyro, StreamKind::kGyro, "gyro", &out->gyro);
  if (s.ok()) s = find(imu.temp, StreamKind::kTemperature, "temp", &out->temp);
  if (!s.ok()) return s;
  if (out->accel == nullptr && out->gyro == nullptr) {
    return StreamsError(path, "needs an accel or a gyro stream");
  }
  return Status::Ok();
}

// The magnetometers `selection` names, else every one of the log.
Status ResolveMags(const SensorLog& log, const LogStreamSelection& selection,
                   std::vector<const SensorStream*>* mags) {
  for (size_t k = 0; k < selection.mags.size(); ++k) {
    const SensorStream* m = FindStream(log, selection.mags[k], StreamKind::kMag);
    if (m == nullptr) {
      return StreamsError("streams.mags[" + std::to_string(k) + "]",
                          "names '" + selection.mags[k] + "', which this " + log.format +
                              " log has no magnetometer stream of; it has: " + StreamList(log));
    }
    mags->push_back(m);
  }
  if (selection.mags.empty()) {
    for (const SensorStream& s : log.streams) {
      if (s.kind == StreamKind::kMag) mags->push_back(&s);
    }
  }
  return Status::Ok();
}

}  // namespace

Status ParseLogStreams(const json& config, LogStreamSelection* selection) {
  *selection = {};
  if (!config.is_object()) return Status::Ok();
  const auto it = config.find("streams");
  if (it == config.end() || it->is_null()) return Status::Ok();
  if (!it->is_object()) {
    return StreamsError("streams", "must be an object {\"imus\": [...], \"mags\": [...]}");
  }
  selection->given = true;
  for (const auto& [key, value] : it->items()) {
    if (key != "imus" && key != "mags") {
      return StreamsError("streams." + key, "is not a key of streams (imus, mags)");
    }
    if (!value.is_array()) return StreamsError("streams." + key, "must be an array");
  }
  if (const auto imus = it->find("imus"); imus != it->end()) {
    for (size_t k = 0; k < imus->size(); ++k) {
      const json& entry = (*imus)[k];
      const std::string path = "streams.imus[" + std::to_string(k) + "]";
      if (!entry.is_object()) {
        return StreamsError(path, "must be an object {\"accel\", \"gyro\", \"temp\"}");
      }
      for (const auto& [key, value] : entry.items()) {
        (void)value;
        if (key != "accel" && key != "gyro" && key != "temp") {
          return StreamsError(path + "." + key, "is not a key of an IMU (accel, gyro, temp)");
        }
      }
      LogStreamSelection::Imu imu;
      Status s = ReadName(entry, "accel", path, &imu.accel);
      if (s.ok()) s = ReadName(entry, "gyro", path, &imu.gyro);
      if (s.ok()) s = ReadName(entry, "temp", path, &imu.temp);
      if (!s.ok()) return s;
      if (imu.accel.empty() && imu.gyro.empty()) {
        return StreamsError(path, "needs \"accel\" or \"gyro\"");
      }
      selection->imus.push_back(imu);
    }
  }
  if (const auto mags = it->find("mags"); mags != it->end()) {
    for (size_t k = 0; k < mags->size(); ++k) {
      const json& name = (*mags)[k];
      if (!name.is_string() || name.get_ref<const std::string&>().empty()) {
        return StreamsError("streams.mags[" + std::to_string(k) + "]", "must be a stream name");
      }
      selection->mags.push_back(name.get<std::string>());
    }
  }
  return Status::Ok();
}

json DescribeStream(const SensorStream& s) {
  const int64_t step = MedianStep(s.t_ns);
  int64_t gaps = 0;
  for (size_t i = 1; i < s.t_ns.size() && step > 0; ++i) {
    if (s.t_ns[i] - s.t_ns[i - 1] > step + step / 2) ++gaps;
  }
  json d = {{"name", s.Name()},
            {"instance", s.instance >= 0 ? json(s.instance) : json(nullptr)},
            {"device_id", s.device_id >= 0 ? json(s.device_id) : json(nullptr)},
            {"kind", StreamKindName(s.kind)},
            {"samples", s.samples()},
            {"rate", step > 0 ? json(1e9 / static_cast<double>(step)) : json(nullptr)},
            {"start", s.t_ns.empty() ? json(nullptr) : json(s.t_ns.front() * 1e-9)},
            {"end", s.t_ns.empty() ? json(nullptr) : json(s.t_ns.back() * 1e-9)},
            {"gaps", gaps},
            {"unit", s.unit},
            {"time_source", s.time_source}};
  if (!s.note.empty()) d["note"] = s.note;
  return d;
}

Status AssembleLog(const SensorLog& log, const LogStreamSelection& selection,
                   const std::string& file_name, AssembledLog* out) {
  *out = {};
  json& description = out->description;
  description = {{"format", log.format}, {"streams", json::array()}};
  json warnings = json::array();
  for (const std::string& w : log.warnings) warnings.push_back(w);
  for (const SensorStream& s : log.streams) description["streams"].push_back(DescribeStream(s));

  const std::vector<LogStreamSelection::Imu> chosen =
      selection.imus.empty() ? DefaultImus(log) : selection.imus;
  if (chosen.empty()) {
    return Status::InvalidInput(
               "the " + log.format +
               " log has no accelerometer or gyroscope stream; it has: " + StreamList(log))
        .WithFile(file_name);
  }
  std::vector<ImuStreams> imus;
  for (size_t k = 0; k < chosen.size(); ++k) {
    ImuStreams imu;
    Status s = Resolve(log, chosen[k], k, &imu);
    if (!s.ok()) return s.WithFile(file_name);
    imus.push_back(imu);
  }

  std::vector<const SensorStream*> mags;
  if (Status s = ResolveMags(log, selection, &mags); !s.ok()) return s.WithFile(file_name);
  const bool on_mag = selection.mag_time_base && !mags.empty();
  // The first IMU's base (or the first magnetometer's) sets the time column; the other IMUs
  // must share it, unless they are all interpolated onto a magnetometer's times.
  const SensorStream* base = on_mag ? mags[0] : imus[0].base();
  int64_t dropped = 0;
  const std::vector<size_t> base_idx = IncreasingSamples(*base, &dropped);
  std::vector<int64_t> t;
  t.reserve(base_idx.size());
  for (size_t i : base_idx) t.push_back(base->t_ns[i]);
  std::vector<ImuStreams> kept;
  for (size_t k = 0; k < imus.size(); ++k) {
    int64_t k_dropped = 0;
    const std::vector<size_t> idx = IncreasingSamples(*imus[k].base(), &k_dropped);
    bool same = idx.size() == t.size();
    for (size_t i = 0; same && i < idx.size(); ++i) same = imus[k].base()->t_ns[idx[i]] == t[i];
    if (same || on_mag) {
      kept.push_back(imus[k]);
      continue;
    }
    const std::string name = imus[k].base()->Name();
    if (selection.given) {
      return StreamsError("streams.imus[" + std::to_string(k) + "]",
                          "uses " + name + ", whose time stamps are not those of " +
                              imus[0].base()->Name() +
                              " (IMU 0): IMUs with their own time bases go in separate jobs, "
                              "one IMU each in `streams`")
          .WithFile(file_name);
    }
    warnings.push_back("the IMU of " + name +
                       " has its own time base, so it was left out of this job "
                       "(one time column per job): calibrate it in a job of its own with "
                       "config streams {\"imus\": [{\"gyro\": \"" +
                       name + "\"...}]}");
  }

  const size_t n = t.size(), K = kept.size();
  if (n < 2) {
    return Status::InvalidInput("the " + log.format + " log has " + std::to_string(n) +
                                " usable samples of " + base->Name())
        .WithFile(file_name);
  }
  // Counted from the first sample's whole second when the clock is an epoch (as for CSV).
  const int64_t first_s = t.front() / 1'000'000'000;
  out->time_origin = t.front() >= static_cast<int64_t>(kTimeOriginSeconds * 1e9) ? first_s : 0;
  ArrayRecording& r = out->recording;
  r.t.resize(static_cast<Eigen::Index>(n));
  const int64_t origin_ns = out->time_origin * 1'000'000'000;
  for (size_t i = 0; i < n; ++i) r.t(static_cast<Eigen::Index>(i)) = (t[i] - origin_ns) * 1e-9;

  int accels = 0, gyros = 0, temps = 0;
  for (const ImuStreams& imu : kept) {
    accels += imu.accel != nullptr;
    gyros += imu.gyro != nullptr;
    temps += imu.temp != nullptr;
  }
  r.accel.resize(static_cast<Eigen::Index>(n), 3 * accels);
  r.gyro.resize(static_cast<Eigen::Index>(n), 3 * gyros);
  r.temperature.resize(static_cast<Eigen::Index>(n), temps);
  r.mag.resize(static_cast<Eigen::Index>(n), 3 * static_cast<Eigen::Index>(mags.size()));
  json imus_json = json::array();
  int a = 0, g = 0, c = 0;
  for (size_t k = 0; k < K; ++k) {
    const ImuStreams& imu = kept[k];
    json d = {{"index", k},
              {"accel", imu.accel ? json(imu.accel->Name()) : json(nullptr)},
              {"gyro", imu.gyro ? json(imu.gyro->Name()) : json(nullptr)},
              {"temp", imu.temp ? json(imu.temp->Name()) : json(nullptr)},
              {"samples", n},
              {"dropped", dropped},
              {"time_source", imu.base()->time_source},
              {"resampled", json::array()}};
    auto fill = [&](const SensorStream* s, Eigen::MatrixXd* m, int column) {
      json resampled = json::array();
      FillColumns(*s, t, m, column, &resampled);
      if (s->kind != StreamKind::kTemperature) {
        for (const json& name : resampled) d["resampled"].push_back(name);
      }
    };
    if (imu.accel != nullptr) {
      r.accel_names.push_back("a" + std::to_string(a));
      fill(imu.accel, &r.accel, 3 * a++);
    }
    if (imu.gyro != nullptr) {
      r.gyro_names.push_back("g" + std::to_string(g));
      fill(imu.gyro, &r.gyro, 3 * g++);
    }
    if (imu.temp != nullptr) {
      r.temp_names.push_back("temp" + std::to_string(k));
      fill(imu.temp, &r.temperature, c++);
      d["temperature"] = "interpolated onto the IMU's times, held at its ends";
    }
    if (!d["resampled"].empty()) {
      warnings.push_back("IMU " + std::to_string(k) + ": " + d["resampled"][0].get<std::string>() +
                         " was interpolated onto " + base->Name() +
                         "'s time stamps (its white noise at the shortest averaging times reads "
                         "low)");
    }
    if (dropped > 0) {
      warnings.push_back("IMU " + std::to_string(k) + ": " + std::to_string(dropped) +
                         " samples of " + base->Name() +
                         " were dropped: their time did not increase");
    }
    imus_json.push_back(d);
  }
  json mags_json = json::array();
  for (size_t j = 0; j < mags.size(); ++j) {
    json d = {{"stream", mags[j]->Name()}, {"resampled", json::array()}};
    r.mag_names.push_back("m" + std::to_string(j));
    r.mag_device_ids.push_back(mags[j]->device_id);
    FillColumns(*mags[j], t, &r.mag, 3 * static_cast<int>(j), &d["resampled"]);
    mags_json.push_back(d);
  }
  description["time_base"] = base->Name() + " (" + base->time_source + ")";
  description["imus"] = imus_json;
  description["mags"] = mags_json;
  description["warnings"] = warnings;
  return Status::Ok();
}

}  // namespace calibd::server
