// ArduPilot DataFlash logs: the sensor streams (formats/dataflash.h).
#include "formats/dataflash.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <tuple>
#include <utility>
#include <vector>

#include "formats/dataflash_format.h"

namespace calibd::server {

namespace {

using dataflash::MessageFormat;

// What calibd reads from which message: one stream per (spec, instance).
struct StreamSpec {
  const char* message;  // the message's name; older logs add the instance's digit ("IMU2")
  StreamKind kind;
  std::array<const char*, 3> fields;  // the first one only for kTemperature
  const char* unit_label;             // the FMTU unit it must have (ArduPilot's UNIT labels)
  double si_per_unit;                 // SI (µT for kMag) per unit_label
  double default_multiplier;          // the unit multiplier when the log has no FMTU
  // The instance's device id parameter: prefix, the instance's number from 2 on (none for
  // instance 0), suffix: INS_ACC_ID, INS_ACC2_ID, ...; COMPASS_DEV_ID, COMPASS_DEV_ID2, ...
  const char* device_param_prefix;
  const char* device_param_suffix;
  // The batch sampler's ISBD: kind and instance from its ISBH, values in SI after dividing by
  // the ISBH's multiplier; its FMTU ("o" for gyro batches too) is not used.
  bool batch = false;
};

constexpr StreamSpec kSpecs[] = {
    {"IMU", StreamKind::kAccel, {"AccX", "AccY", "AccZ"}, "m/s/s", 1, 1, "INS_ACC", "_ID"},
    {"IMU", StreamKind::kGyro, {"GyrX", "GyrY", "GyrZ"}, "rad/s", 1, 1, "INS_GYR", "_ID"},
    {"IMU", StreamKind::kTemperature, {"T", nullptr, nullptr}, "degC", 1, 1, "INS_ACC", "_ID"},
    {"ACC", StreamKind::kAccel, {"AccX", "AccY", "AccZ"}, "m/s/s", 1, 1, "INS_ACC", "_ID"},
    {"GYR", StreamKind::kGyro, {"GyrX", "GyrY", "GyrZ"}, "rad/s", 1, 1, "INS_GYR", "_ID"},
    // 1 gauss = 100 µT; ArduPilot logs milligauss.
    {"MAG", StreamKind::kMag, {"MagX", "MagY", "MagZ"}, "Gauss", 100, 1e-3, "COMPASS_DEV_ID", ""},
    {"ISBD", StreamKind::kAccel, {"x", "y", "z"}, "m/s/s", 1, 1, "INS_ACC", "_ID", true},
    {"ISBD", StreamKind::kGyro, {"x", "y", "z"}, "rad/s", 1, 1, "INS_GYR", "_ID", true},
};
constexpr int kSpecCount = sizeof(kSpecs) / sizeof(kSpecs[0]);
// The ISBD accel and gyro specs, by an ISBH's sensor type (0 accel, 1 gyro).
constexpr int kBatchSpec[2] = {kSpecCount - 2, kSpecCount - 1};
static_assert(kSpecs[kBatchSpec[0]].batch && kSpecs[kBatchSpec[0]].kind == StreamKind::kAccel &&
              kSpecs[kBatchSpec[1]].batch && kSpecs[kBatchSpec[1]].kind == StreamKind::kGyro);

// ArduPilot's unit and multiplier ids (LogStructure.h log_Units, log_Multipliers) for a log whose
// FMTU names them without UNIT or MULT messages.
const char* BuiltinUnitLabel(char id) {
  switch (id) {
    case 'o':
      return "m/s/s";
    case 'E':
      return "rad/s";
    case 'O':
      return "degC";
    case 'G':
      return "Gauss";
    default:
      return nullptr;
  }
}
// 0 when `id` is not a power of ten ArduPilot defines.
double BuiltinMultiplier(char id) {
  static constexpr std::pair<char, double> kTable[] = {
      {'2', 1e2},  {'1', 1e1},  {'0', 1},    {'A', 1e-1}, {'B', 1e-2}, {'C', 1e-3},
      {'D', 1e-4}, {'E', 1e-5}, {'F', 1e-6}, {'G', 1e-7}, {'I', 1e-9}};
  for (const auto& [key, value] : kTable)
    if (key == id) return value;
  return 0;
}
// MULT messages store ArduPilot's multipliers, powers of ten, through a float: 0.001 arrives as
// 0.0010000000474974513. Snaps such a value to the power of ten it stands for.
double SnapToPowerOfTen(double m) {
  if (!(m > 0) || !std::isfinite(m)) return m;
  const double p = std::pow(10.0, std::round(std::log10(m)));
  return std::fabs(m / p - 1) < 1e-6 ? p : m;
}

// The metadata messages calibd reads, and the fields it reads from them.
enum class Role { kSkip, kFmt, kFmtu, kUnit, kMult, kParm, kSensor, kBatchHeader, kBatchData };

// ISBH (one batch of the batch sampler) and ISBD (32 samples of it): the fields read, in order.
constexpr const char* kBatchHeaderFields[] = {"N",       "type",     "instance", "mul",
                                              "smp_cnt", "SampleUS", "smp_rate"};
constexpr const char* kBatchDataFields[] = {"N", "seqno", "x", "y", "z"};
constexpr int kBatchSamplesPerMessage = 32;

// A batch as its ISBH describes it.
struct Batch {
  int spec = 0;  // the ISBD accel or gyro spec
  int instance = 0;
  double multiplier = 1;  // stored value = reading × multiplier
  int64_t samples = 0;    // in the batch
  int64_t first_ns = 0;   // time of its first sample
  double rate_hz = 0;     // sample k at first_ns + k / rate_hz
};

// One stream a sensor message type feeds.
struct BoundStream {
  int spec = 0;                     // index in kSpecs
  std::array<int, 3> field{};       // field indices in the format
  std::array<int, 256> state_of{};  // instance -> index in Reader::states_, -1 until first seen
};

// How to read one message type, from its FMT.
struct TypeReader {
  bool defined = false;
  Role role = Role::kSkip;
  MessageFormat format;
  // kSensor: the instance (field `I`, or the digit of an older name) and the time fields.
  int instance_field = -1;
  int fixed_instance = 0;
  bool older_name = false;
  int sample_us = -1, time_us = -1, time_ms = -1;  // field indices, -1 when absent
  std::vector<BoundStream> streams;
  // Metadata roles: the field indices they read (kFmtu: FmtType, UnitIds, MultIds; kUnit: Id,
  // Label; kMult: Id, Mult; kParm: Name, Value).
  std::array<int, 3> meta{};
  // kBatchHeader, kBatchData: the indices of kBatchHeaderFields or kBatchDataFields.
  std::array<int, 7> batch{};
};

// A stream being read, with what its finishing needs.
struct StreamState {
  SensorStream stream;
  int spec = 0;
  uint8_t type = 0;            // the message type that defined it (FMTU lookup)
  std::array<int, 3> field{};  // its fields' indices in that type (FMTU lookup)
  // The logging times (TimeUS or TimeMS, as stream.time_source says) once a sample came with a
  // SampleUS: t_ns then holds SampleUS where there was one, and the stream falls back to these
  // when any sample lacked it (zero, or a message type without it).
  std::vector<int64_t> fallback;
  int64_t without_sample_time = 0;
};

// Times in a message: sample time (when the type has SampleUS) and the logging time, in ns.
struct MessageTimes {
  int64_t sample = 0, logged = 0;
  bool has_sample = false;
};

class Reader {
 public:
  Reader(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits)
      : data_(reinterpret_cast<const uint8_t*>(bytes.data())),
        size_(static_cast<int64_t>(bytes.size())),
        file_name_(file_name),
        limits_(limits) {
    TypeReader& fmt = types_[dataflash::kFmtType];
    fmt.defined = true;
    fmt.role = Role::kFmt;
    fmt.format.type = dataflash::kFmtType;
    fmt.format.length = dataflash::kFmtLength;
    fmt.format.name = "FMT";
  }

  Status Run(SensorLog* log);

 private:
  Status HandleMessage(TypeReader& reader, const uint8_t* p, int64_t offset);
  Status HandleFmt(const uint8_t* p, int64_t offset);
  void HandleMetadata(const TypeReader& reader, const uint8_t* p);
  Status HandleSensor(TypeReader& reader, const uint8_t* p, int64_t offset);
  Status ReadTimes(const TypeReader& reader, const uint8_t* p, int64_t offset,
                   MessageTimes* times) const;
  void Bind(TypeReader* reader) const;
  int StateFor(const TypeReader& reader, BoundStream* bound, int instance);
  int StateIndex(const TypeReader& reader, int spec, int instance, const std::array<int, 3>& field);
  void HandleBatchHeader(const TypeReader& reader, const uint8_t* p);
  Status HandleBatchData(const TypeReader& reader, const uint8_t* p, int64_t offset);
  void Finish(SensorLog* log);
  bool ApplyUnits(StreamState* state, std::vector<std::string>* warnings) const;
  Status Damage(int64_t offset, const std::string& what) const;

  const uint8_t* data_;
  int64_t size_;
  const std::string& file_name_;
  const SensorLogLimits& limits_;
  std::array<TypeReader, 256> types_;
  int64_t messages_ = 0;  // whole messages read
  int64_t samples_ = 0;   // over all streams
  bool saw_fmt_ = false;
  std::vector<StreamState> states_;
  std::map<std::pair<int, int>, int> state_index_;  // (spec, instance) -> states_ index
  // Metadata: FMTU per type (unit ids, multiplier ids), UNIT labels, MULT values, PARM values.
  std::map<uint8_t, std::pair<std::string, std::string>> fmtu_;
  std::map<char, std::string> unit_labels_;
  std::map<char, double> multipliers_;
  std::map<std::string, double> params_;
  std::map<int64_t, Batch> batches_;  // by ISBH N
  int64_t unread_batch_data_ = 0;     // ISBD without a valid ISBH
};

Status Reader::Damage(int64_t offset, const std::string& what) const {
  return Status::InvalidInput("damaged DataFlash log: byte " + std::to_string(offset) +
                              ", message " + std::to_string(messages_ + 1) + ": " + what)
      .WithFile(file_name_);
}

Status Reader::Run(SensorLog* log) {
  int64_t junk_bytes = 0, junk_runs = 0, first_junk = -1;
  bool in_junk = false;
  int64_t pos = 0;
  while (pos < size_) {
    const int64_t left = size_ - pos;
    const uint8_t* p = data_ + pos;
    TypeReader* reader = nullptr;
    if (p[0] == dataflash::kHead1 && (left < 2 || p[1] == dataflash::kHead2)) {
      if (left < dataflash::kHeaderBytes) {
        log->warnings.push_back("log cut at byte " + std::to_string(pos) +
                                " in the header of a message (a power-off?): read up to there");
        break;
      }
      if (types_[p[2]].defined) reader = &types_[p[2]];
    }
    if (reader == nullptr) {  // junk: skip to the next 0xA3
      if (!in_junk) ++junk_runs;
      if (first_junk < 0) first_junk = pos;
      in_junk = true;
      const void* next = std::memchr(p + 1, dataflash::kHead1, static_cast<size_t>(left - 1));
      const int64_t skip = next ? static_cast<const uint8_t*>(next) - p : left;
      junk_bytes += skip;
      pos += skip;
      continue;
    }
    in_junk = false;
    if (left < reader->format.length) {
      log->warnings.push_back("log cut at byte " + std::to_string(pos) + " in the middle of a " +
                              reader->format.name + " message (a power-off?): read up to there");
      break;
    }
    Status s = HandleMessage(*reader, p, pos);
    if (!s.ok()) return s;
    ++messages_;
    pos += reader->format.length;
  }
  if (!saw_fmt_)
    return Status::InvalidInput("not a DataFlash log: no FMT message (0xA3 0x95 0x80) in its " +
                                std::to_string(size_) + " bytes")
        .WithFile(file_name_);
  if (junk_bytes > 0)
    log->warnings.push_back("skipped " + std::to_string(junk_bytes) +
                            " bytes that are not DataFlash messages in " +
                            std::to_string(junk_runs) + " places (the first at byte " +
                            std::to_string(first_junk) + "), as ArduPilot's tools do");
  Finish(log);
  return Status::Ok();
}

Status Reader::HandleMessage(TypeReader& reader, const uint8_t* p, int64_t offset) {
  switch (reader.role) {
    case Role::kFmt:
      return HandleFmt(p, offset);
    case Role::kSensor:
      return HandleSensor(reader, p, offset);
    case Role::kSkip:
      return Status::Ok();
    case Role::kBatchHeader:
      HandleBatchHeader(reader, p);
      return Status::Ok();
    case Role::kBatchData:
      return HandleBatchData(reader, p, offset);
    default:
      HandleMetadata(reader, p);
      return Status::Ok();
  }
}

Status Reader::HandleFmt(const uint8_t* p, int64_t offset) {
  MessageFormat format;
  std::string why;
  const bool ok = dataflash::ParseFmt(p + dataflash::kHeaderBytes, &format, &why);
  const std::string which =
      "FMT of type " + std::to_string(format.type) + " (\"" + format.name + "\")";
  if (!ok) return Damage(offset, which + ": " + why);
  if (format.type == dataflash::kFmtType &&
      (format.length != dataflash::kFmtLength || format.format != "BBnNZ"))
    return Damage(offset, which + " redefines FMT as " + std::to_string(format.length) +
                              " bytes \"" + format.format + "\", not 89 bytes \"BBnNZ\"");
  saw_fmt_ = true;
  if (format.type == dataflash::kFmtType) return Status::Ok();
  TypeReader& reader = types_[format.type];
  reader = TypeReader();
  reader.defined = true;
  reader.format = std::move(format);
  Bind(&reader);
  return Status::Ok();
}

// Decides the role of a newly defined type and the fields it reads.
void Reader::Bind(TypeReader* reader) const {
  const MessageFormat& f = reader->format;
  // The index of field `label` when its format character is one of `chars`, else -1.
  const auto field = [&](const char* label, const char* chars) {
    const int i = f.FieldIndex(label);
    return i >= 0 && std::strchr(chars, f.format[i]) != nullptr ? i : -1;
  };
  constexpr const char* kId = "bBM";  // a char or uint8 id
  constexpr const char* kText = "nNZ";
  constexpr const char* kNumber = "bBMhHiIqQcCeELfdg";
  const auto metadata = [&](Role role, int a, int b, int c) {
    reader->meta = {a, b, c};
    if (a >= 0 && b >= 0 && c >= 0) reader->role = role;
  };
  if (f.name == "FMTU")
    return metadata(Role::kFmtu, field("FmtType", kId), field("UnitIds", kText),
                    field("MultIds", kText));
  if (f.name == "UNIT") return metadata(Role::kUnit, field("Id", kId), field("Label", kText), 0);
  if (f.name == "MULT") return metadata(Role::kMult, field("Id", kId), field("Mult", kNumber), 0);
  if (f.name == "PARM")
    return metadata(Role::kParm, field("Name", kText), field("Value", kNumber), 0);
  const auto batch = [&](Role role, const auto& labels) {
    bool complete = true;
    for (size_t k = 0; k < std::size(labels); ++k) {
      const bool array = role == Role::kBatchData && k >= 2;
      const bool rate = role == Role::kBatchHeader && k == 6;
      reader->batch[k] = field(labels[k], array ? "a" : rate ? kNumber : "bBMhHiIqQ");
      complete = complete && reader->batch[k] >= 0;
    }
    if (complete) reader->role = role;
  };
  if (f.name == "ISBH") return batch(Role::kBatchHeader, kBatchHeaderFields);
  if (f.name == "ISBD") return batch(Role::kBatchData, kBatchDataFields);

  for (int s = 0; s < kSpecCount; ++s) {
    if (kSpecs[s].batch) continue;
    const std::string base = kSpecs[s].message;
    int fixed_instance = 0;
    if (f.name.size() == base.size() + 1 && f.name.compare(0, base.size(), base) == 0 &&
        f.name.back() >= '2' && f.name.back() <= '9') {
      fixed_instance = f.name.back() - '1';  // IMU2 is instance 1
    } else if (f.name != base) {
      continue;
    }
    BoundStream bound;
    bound.spec = s;
    bool complete = true;
    for (int k = 0; k < StreamDimension(kSpecs[s].kind); ++k)
      complete = complete && (bound.field[k] = field(kSpecs[s].fields[k], kNumber)) >= 0;
    if (!complete) continue;
    bound.state_of.fill(-1);
    reader->streams.push_back(bound);
    reader->fixed_instance = fixed_instance;
    reader->older_name = fixed_instance > 0;
  }
  const auto integer = [&](const char* label) {
    const int i = f.FieldIndex(label);
    return i >= 0 && dataflash::IsIntegerField(f.format[i]) ? i : -1;
  };
  reader->instance_field = reader->older_name ? -1 : integer("I");
  reader->sample_us = integer("SampleUS");
  reader->time_us = integer("TimeUS");
  reader->time_ms = integer("TimeMS");
  // A message without a time (the oldest IMU) cannot be read as a stream.
  if (!reader->streams.empty() && (reader->time_us >= 0 || reader->time_ms >= 0))
    reader->role = Role::kSensor;
}

void Reader::HandleMetadata(const TypeReader& reader, const uint8_t* p) {
  const MessageFormat& f = reader.format;
  const auto scalar = [&](int k) {
    return dataflash::ReadScalar(p + f.offsets[reader.meta[k]], f.format[reader.meta[k]]);
  };
  const auto text = [&](int k) {
    return dataflash::ReadText(p + f.offsets[reader.meta[k]], f.format[reader.meta[k]]);
  };
  const auto id = [&] { return p[f.offsets[reader.meta[0]]]; };  // one byte (Bind)
  switch (reader.role) {
    case Role::kFmtu:
      fmtu_[id()] = {text(1), text(2)};
      break;
    case Role::kUnit:
      unit_labels_[static_cast<char>(id())] = text(1);
      break;
    case Role::kMult:
      multipliers_[static_cast<char>(id())] = SnapToPowerOfTen(scalar(1));
      break;
    default:  // kParm
      params_[text(0)] = scalar(1);
      break;
  }
}

Status Reader::ReadTimes(const TypeReader& reader, const uint8_t* p, int64_t offset,
                         MessageTimes* times) const {
  const MessageFormat& f = reader.format;
  const auto ns = [&](int field, int64_t ns_per_unit, int64_t* out) {
    const int64_t v = dataflash::ReadInteger(p + f.offsets[field], f.format[field]);
    if (v < 0 || v > std::numeric_limits<int64_t>::max() / ns_per_unit) return false;
    *out = v * ns_per_unit;
    return true;
  };
  const int logged = reader.time_us >= 0 ? reader.time_us : reader.time_ms;
  if (!ns(logged, reader.time_us >= 0 ? 1000 : 1000000, &times->logged))
    return Damage(offset, f.name + " time " + f.labels[logged] + " is out of range");
  times->has_sample = reader.sample_us >= 0;
  if (times->has_sample && !ns(reader.sample_us, 1000, &times->sample))
    return Damage(offset, f.name + " time SampleUS is out of range");
  return Status::Ok();
}

// The states_ index of the stream `bound` feeds for `instance`, created on first use.
int Reader::StateFor(const TypeReader& reader, BoundStream* bound, int instance) {
  int& cached = bound->state_of[instance];
  if (cached < 0) cached = StateIndex(reader, bound->spec, instance, bound->field);
  return cached;
}

// The states_ index of the stream of (spec, instance), created on first use from `reader`'s
// message type and `field`.
int Reader::StateIndex(const TypeReader& reader, int spec_index, int instance,
                       const std::array<int, 3>& field) {
  auto [it, inserted] = state_index_.try_emplace({spec_index, instance}, 0);
  if (inserted) {
    const StreamSpec& spec = kSpecs[spec_index];
    it->second = static_cast<int>(states_.size());
    StreamState state;
    state.spec = spec_index;
    state.type = reader.format.type;
    state.field = field;
    state.stream.kind = spec.kind;
    state.stream.topic = spec.message;
    state.stream.instance = instance;
    // The logging time's name; Finish() makes it SampleUS when every sample had one. A batch's
    // samples are timed from its ISBH's SampleUS.
    state.stream.time_source = spec.batch ? "SampleUS" : reader.time_us >= 0 ? "TimeUS" : "TimeMS";
    if (reader.older_name)
      state.stream.note =
          "logged as " + reader.format.name + " (older ArduPilot: one message name per instance)";
    states_.push_back(std::move(state));
  }
  return it->second;
}

Status Reader::HandleSensor(TypeReader& reader, const uint8_t* p, int64_t offset) {
  const MessageFormat& f = reader.format;
  int64_t instance = reader.fixed_instance;
  if (reader.instance_field >= 0)
    instance = dataflash::ReadInteger(p + f.offsets[reader.instance_field],
                                      f.format[reader.instance_field]);
  if (instance < 0 || instance > 255)
    return Damage(offset, f.name + " instance I = " + std::to_string(instance) + " out of range");
  MessageTimes times;
  Status s = ReadTimes(reader, p, offset, &times);
  if (!s.ok()) return s;
  for (BoundStream& bound : reader.streams) {
    StreamState& state = states_[StateFor(reader, &bound, static_cast<int>(instance))];
    SensorStream& stream = state.stream;
    if (++samples_ > limits_.max_samples)
      return Damage(offset, "more than " + std::to_string(limits_.max_samples) +
                                " samples (the limit on samples per log)");
    if (times.has_sample || !state.fallback.empty()) {
      if (state.fallback.empty()) {  // the samples before had only their logging time
        state.fallback = stream.t_ns;
        state.without_sample_time += stream.samples();
      }
      state.without_sample_time += !times.has_sample || times.sample == 0;
      stream.t_ns.push_back(times.has_sample ? times.sample : times.logged);
      state.fallback.push_back(times.logged);
    } else {
      stream.t_ns.push_back(times.logged);
    }
    for (int k = 0; k < StreamDimension(stream.kind); ++k)
      stream.values.push_back(
          dataflash::ReadScalar(p + f.offsets[bound.field[k]], f.format[bound.field[k]]));
  }
  return Status::Ok();
}

// Remembers the batch an ISBH describes; one that cannot be read (an unknown sensor type, a
// multiplier or rate that is not positive, a time out of range) is forgotten, so that its ISBD
// count as unread.
void Reader::HandleBatchHeader(const TypeReader& reader, const uint8_t* p) {
  const MessageFormat& f = reader.format;
  const auto value = [&](int k) {
    return dataflash::ReadScalar(p + f.offsets[reader.batch[k]], f.format[reader.batch[k]]);
  };
  const auto integer = [&](int k) {
    return dataflash::ReadInteger(p + f.offsets[reader.batch[k]], f.format[reader.batch[k]]);
  };
  const int64_t n = integer(0), type = integer(1), instance = integer(2), samples = integer(4),
                sample_us = integer(5);
  const double multiplier = value(3), rate = value(6);
  // Room for a batch's last offset (65 535 samples at 1 Hz) after its first time.
  constexpr int64_t kMaxFirstUs = (std::numeric_limits<int64_t>::max() - (int64_t{1} << 47)) / 1000;
  if ((type != 0 && type != 1) || instance < 0 || instance > 255 || !(multiplier > 0) ||
      !(rate >= 1 && rate <= 1e6) || samples <= 0 || samples > 65535 || sample_us < 0 ||
      sample_us > kMaxFirstUs) {
    batches_.erase(n);
    return;
  }
  Batch& batch = batches_[n];
  batch.spec = kBatchSpec[type];
  batch.instance = static_cast<int>(instance);
  batch.multiplier = multiplier;
  batch.samples = samples;
  batch.first_ns = sample_us * 1000;
  batch.rate_hz = rate;
}

// Appends the (up to) 32 samples of an ISBD to its batch's stream.
Status Reader::HandleBatchData(const TypeReader& reader, const uint8_t* p, int64_t offset) {
  const MessageFormat& f = reader.format;
  const auto& at = reader.batch;
  const auto found = batches_.find(dataflash::ReadInteger(p + f.offsets[at[0]], f.format[at[0]]));
  const int64_t first =
      kBatchSamplesPerMessage * dataflash::ReadInteger(p + f.offsets[at[1]], f.format[at[1]]);
  if (found == batches_.end() || first < 0 || first >= found->second.samples) {
    ++unread_batch_data_;
    return Status::Ok();
  }
  const Batch& batch = found->second;
  StreamState& state =
      states_[StateIndex(reader, batch.spec, batch.instance, {at[2], at[3], at[4]})];
  for (int j = 0; j < kBatchSamplesPerMessage && first + j < batch.samples; ++j) {
    if (++samples_ > limits_.max_samples)
      return Damage(offset, "more than " + std::to_string(limits_.max_samples) +
                                " samples (the limit on samples per log)");
    state.stream.t_ns.push_back(batch.first_ns +
                                std::llround(static_cast<double>(first + j) * 1e9 / batch.rate_hz));
    for (int k = 2; k < 5; ++k)
      state.stream.values.push_back(dataflash::ReadArrayElement(p + f.offsets[at[k]], j) /
                                    batch.multiplier);
  }
  return Status::Ok();
}

// Converts a stream's values to SI from the unit and multiplier its FMTU gives (else the
// defaults), and sets its unit. False when the FMTU gives another unit than the stream's.
bool Reader::ApplyUnits(StreamState* state, std::vector<std::string>* warnings) const {
  const StreamSpec& spec = kSpecs[state->spec];
  std::string label = spec.unit_label;
  double multiplier = spec.default_multiplier;
  const auto found = spec.batch ? fmtu_.end() : fmtu_.find(state->type);
  const auto field = static_cast<size_t>(state->field[0]);
  if (found != fmtu_.end() && field < found->second.first.size() &&
      field < found->second.second.size()) {
    const char unit_id = found->second.first[field];
    const char mult_id = found->second.second[field];
    const auto unit = unit_labels_.find(unit_id);
    const char* builtin = BuiltinUnitLabel(unit_id);
    label = unit != unit_labels_.end() ? unit->second
            : builtin                  ? builtin
                                       : "unit '" + std::string(1, unit_id) + "'";
    const auto mult = multipliers_.find(mult_id);
    const double value = mult != multipliers_.end() ? mult->second : BuiltinMultiplier(mult_id);
    // '-' (none) and '?' (unknown) leave the default.
    if (value > 0 && mult_id != '-' && mult_id != '?') multiplier = value;
  }
  const std::string name = state->stream.Name() + " " + StreamKindName(state->stream.kind);
  if (label != spec.unit_label) {
    warnings->push_back(name + " not read: the log's FMTU gives its unit as " + label + ", not " +
                        spec.unit_label);
    return false;
  }
  const double factor = multiplier * spec.si_per_unit;
  if (factor != 1)
    for (double& v : state->stream.values) v *= factor;
  if (multiplier == 1) {
    state->stream.unit = label;
  } else {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g ", multiplier);
    state->stream.unit = buf + label;
  }
  return true;
}

void Reader::Finish(SensorLog* log) {
  // In the order of kSpecs' messages (IMU, ACC, GYR, MAG), then by instance, then by kind.
  const auto key = [](const StreamState& s) {
    int topic = 0;
    while (std::strcmp(kSpecs[topic].message, kSpecs[s.spec].message) != 0) ++topic;
    return std::make_tuple(topic, s.stream.instance, s.spec);
  };
  std::sort(states_.begin(), states_.end(),
            [&](const StreamState& a, const StreamState& b) { return key(a) < key(b); });
  for (StreamState& state : states_) {
    SensorStream& stream = state.stream;
    if (!state.fallback.empty() && state.without_sample_time == 0) {
      stream.time_source = "SampleUS";
    } else if (!state.fallback.empty()) {
      stream.t_ns = std::move(state.fallback);
      if (!stream.note.empty()) stream.note += "; ";
      stream.note += "SampleUS is zero or absent in " + std::to_string(state.without_sample_time) +
                     " of " + std::to_string(stream.samples()) + " samples: the logging time " +
                     stream.time_source + " is used";
    }
    if (!ApplyUnits(&state, &log->warnings)) continue;
    const StreamSpec& spec = kSpecs[state.spec];
    const std::string param =
        spec.device_param_prefix +
        (stream.instance > 0 ? std::to_string(stream.instance + 1) : std::string()) +
        spec.device_param_suffix;
    const auto id = params_.find(param);
    if (id != params_.end() && id->second > 0 && id->second < 2147483648.0 &&
        id->second == std::floor(id->second))
      stream.device_id = static_cast<int64_t>(id->second);
    log->streams.push_back(std::move(stream));
  }
  if (unread_batch_data_ > 0)
    log->warnings.push_back(std::to_string(unread_batch_data_) +
                            " ISBD messages (batch sampler) not read: their ISBH was lost, "
                            "unreadable, or describes fewer samples");
  if (log->streams.empty())
    log->warnings.push_back("no IMU, ACC, GYR, MAG or ISBD messages with their fields in the log");
}

}  // namespace

Status ReadDataFlash(std::string_view bytes, const std::string& file_name,
                     const SensorLogLimits& limits, SensorLog* log) {
  *log = SensorLog();
  log->format = "dataflash";
  auto reader = std::make_unique<Reader>(bytes, file_name, limits);
  Status s = reader->Run(log);
  if (!s.ok()) *log = SensorLog();
  return s;
}

}  // namespace calibd::server
