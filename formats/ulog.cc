// PX4 ULog reader: the header, the message framing, definitions and subscriptions, cuts and
// appended data (formats/ulog.h). The sensor topics' data go to formats/ulog_sensors.
#include "formats/ulog.h"

#include <cstring>
#include <unordered_map>
#include <utility>
#include <vector>

#include "formats/ulog_definitions.h"
#include "formats/ulog_sensors.h"

namespace calibd::server {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the ULog reader assumes a LE host");

namespace {

constexpr std::string_view kMagic("ULog\x01\x12\x35", 7);
constexpr size_t kHeaderBytes = 16;        // magic, version, uint64 µs timestamp
constexpr size_t kMessageHeaderBytes = 3;  // uint16 payload size, uint8 type
constexpr size_t kFlagBitsBytes = 40;      // 8 compat, 8 incompat flags, 3 uint64 offsets
constexpr uint8_t kIncompatDataAppended = 0x1;

uint16_t LoadU16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | (p[1] << 8)); }
uint64_t LoadU64(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

std::string TypeName(uint8_t type) {
  if (type >= 0x20 && type < 0x7f) return std::string("'") + static_cast<char>(type) + "'";
  return "type " + std::to_string(type);
}

// One pass over the bytes. Not reusable.
class ULogReader {
 public:
  ULogReader(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits)
      : bytes_(bytes), file_name_(file_name), sensors_(limits) {}

  Status Read(SensorLog* log);

 private:
  struct Subscription {
    std::string topic;
    int64_t min_size = 0;  // data bytes a 'D' holds at least (ulog::Layout)
    int64_t size = 0;      // and at most
    int handle = -1;       // ulog::SensorStreams handle, -1 when not a sensor topic
  };

  // kInvalidInput naming the current message and its offset.
  Status Fail(const std::string& what) const;
  // Next end of the bytes a message may reach: the next appended-data offset or the file's end.
  size_t SegmentEnd() const;
  Status Message(uint8_t type, const uint8_t* payload, size_t size);
  Status FlagBits(const uint8_t* payload, size_t size);
  Status AddLogged(const uint8_t* payload, size_t size);
  Status Data(const uint8_t* payload, size_t size);

  std::string_view bytes_;
  const std::string& file_name_;
  size_t pos_ = 0;     // start of the current message
  int64_t index_ = 0;  // the current message's index (0 = first after the header)
  uint8_t type_ = 0;   // the current message's type and payload size, for messages
  size_t size_ = 0;
  std::vector<size_t> appended_;  // appended-data offsets still ahead, ascending
  ulog::Definitions definitions_;
  ulog::SensorStreams sensors_;
  std::unordered_map<uint16_t, Subscription> subscriptions_;
  std::vector<std::string> warnings_;
};

Status ULogReader::Fail(const std::string& what) const {
  return Status::InvalidInput("ULog damaged at byte " + std::to_string(pos_) + " (message " +
                              std::to_string(index_) + ", " + TypeName(type_) + " of " +
                              std::to_string(size_) + " bytes): " + what)
      .WithFile(file_name_);
}

size_t ULogReader::SegmentEnd() const {
  return appended_.empty() ? bytes_.size() : appended_.front();
}

Status ULogReader::Read(SensorLog* log) {
  if (bytes_.size() < kHeaderBytes || bytes_.substr(0, kMagic.size()) != kMagic)
    return Status::InvalidInput("not a ULog file: it does not start with the 16-byte ULog header")
        .WithFile(file_name_);
  const auto* data = reinterpret_cast<const uint8_t*>(bytes_.data());
  if (data[kMagic.size()] > 1)
    warnings_.push_back("ULog version " + std::to_string(data[kMagic.size()]) +
                        " is newer than this reader's (1): read as version 1");
  pos_ = kHeaderBytes;
  while (pos_ < bytes_.size()) {
    const size_t end = SegmentEnd();
    const bool header_fits = end - pos_ >= kMessageHeaderBytes;
    const size_t size = header_fits ? LoadU16(data + pos_) : 0;
    if (!header_fits || end - pos_ - kMessageHeaderBytes < size) {
      if (end == bytes_.size()) {
        warnings_.push_back("log cut at byte " + std::to_string(pos_) +
                            " in the middle of a message (a power-off?): read up to there");
        break;
      }
      warnings_.push_back("log cut at byte " + std::to_string(pos_) +
                          " in the middle of a message, before data appended at byte " +
                          std::to_string(end) + ": read up to there, then the appended data");
      pos_ = end;
    } else {
      type_ = data[pos_ + 2];
      size_ = size;
      Status status = Message(type_, data + pos_ + kMessageHeaderBytes, size);
      if (!status.ok()) return status;
      pos_ += kMessageHeaderBytes + size;
      ++index_;
    }
    while (!appended_.empty() && appended_.front() <= pos_) appended_.erase(appended_.begin());
  }
  *log = SensorLog();
  log->format = "ulog";
  log->warnings = std::move(warnings_);
  sensors_.Finish(log);
  return Status::Ok();
}

Status ULogReader::Message(uint8_t type, const uint8_t* payload, size_t size) {
  // Minimum payloads: a key length byte and key ('I', 'P'), is_continued or default_types
  // first ('M', 'Q'), log level and µs timestamp ('L'; 'C' adds a uint16 tag), 8 sync bytes.
  size_t key_at = 0;
  switch (type) {
    case 'B':
      return FlagBits(payload, size);
    case 'F': {
      Status status =
          definitions_.AddFormat(std::string_view(reinterpret_cast<const char*>(payload), size));
      return status.ok() ? status : Fail(status.message());
    }
    case 'A':
      return AddLogged(payload, size);
    case 'R':
      if (size < 2) return Fail("a remove message ('R') holds a uint16 msg_id");
      subscriptions_.erase(LoadU16(payload));
      return Status::Ok();
    case 'D':
      return Data(payload, size);
    case 'M':
    case 'Q':
      key_at = 1;
      [[fallthrough]];
    case 'I':
    case 'P':
      if (size < key_at + 1 || size < key_at + 1 + payload[key_at])
        return Fail("the key length runs past the message");
      return Status::Ok();
    case 'L':
      return size < 9 ? Fail("a log text ('L') holds a level and a timestamp") : Status::Ok();
    case 'C':
      return size < 11 ? Fail("a tagged log text ('C') holds a level, tag and timestamp")
                       : Status::Ok();
    case 'S':
      return size < 8 ? Fail("a sync message ('S') holds 8 bytes") : Status::Ok();
    case 'O':
      return size < 2 ? Fail("a dropout message ('O') holds a uint16 duration") : Status::Ok();
    case 0:
      return Fail("message type 0 is not a ULog message");
    default:
      return Status::Ok();  // a type this reader does not know: skipped, as the format asks
  }
}

Status ULogReader::FlagBits(const uint8_t* payload, size_t size) {
  if (index_ != 0) return Fail("the flag bits ('B') must be the first message");
  if (size < kFlagBitsBytes)
    return Fail("the flag bits ('B') hold 40 bytes: compat, incompat flags, appended offsets");
  const uint8_t* incompat = payload + 8;
  bool unknown = (incompat[0] & ~kIncompatDataAppended) != 0;
  for (int i = 1; i < 8; ++i) unknown = unknown || incompat[i] != 0;
  if (unknown)
    return Fail("unknown incompatible flags are set: this log needs a newer ULog reader");
  if (!(incompat[0] & kIncompatDataAppended)) return Status::Ok();
  size_t previous = pos_ + kMessageHeaderBytes + size;
  for (int i = 0; i < 3; ++i) {
    const uint64_t offset = LoadU64(payload + 16 + 8 * i);
    if (offset == 0) break;
    if (offset < previous)
      return Fail("appended-data offset " + std::to_string(offset) + " lies before byte " +
                  std::to_string(previous));
    if (offset > bytes_.size()) {
      warnings_.push_back("data appended at byte " + std::to_string(offset) +
                          " is missing: the file ends at byte " + std::to_string(bytes_.size()));
      break;
    }
    appended_.push_back(static_cast<size_t>(offset));
    previous = static_cast<size_t>(offset);
  }
  return Status::Ok();
}

Status ULogReader::AddLogged(const uint8_t* payload, size_t size) {
  if (size < 4) return Fail("a subscription ('A') holds multi_id, msg_id and a name");
  const int multi_id = payload[0];
  const uint16_t msg_id = LoadU16(payload + 1);
  std::string_view name(reinterpret_cast<const char*>(payload + 3), size - 3);
  name = name.substr(0, name.find('\0'));
  Subscription s;
  s.topic = std::string(name);
  const ulog::Layout* layout = nullptr;
  Status status = definitions_.GetLayout(s.topic, &layout);
  if (!status.ok())
    return Fail("subscription of msg_id " + std::to_string(msg_id) + ": " + status.message());
  s.min_size = layout->min_size;
  s.size = layout->size;
  s.handle = sensors_.Subscribe(s.topic, multi_id, *layout, &warnings_);
  subscriptions_[msg_id] = std::move(s);
  return Status::Ok();
}

Status ULogReader::Data(const uint8_t* payload, size_t size) {
  if (size < 2) return Fail("a data message ('D') holds a uint16 msg_id");
  const uint16_t msg_id = LoadU16(payload);
  auto it = subscriptions_.find(msg_id);
  if (it == subscriptions_.end())
    return Fail("msg_id " + std::to_string(msg_id) + " is not subscribed (no 'A' message)");
  const Subscription& s = it->second;
  const int64_t data_size = static_cast<int64_t>(size) - 2;
  if (data_size < s.min_size || data_size > s.size)
    return Fail(std::to_string(data_size) + " bytes of " + s.topic + " data, its format holds " +
                (s.min_size == s.size
                     ? std::to_string(s.size)
                     : std::to_string(s.min_size) + " to " + std::to_string(s.size)));
  if (s.handle < 0) return Status::Ok();
  Status status = sensors_.Add(s.handle, payload + 2);
  return status.ok() ? status : Fail(s.topic + ": " + status.message());
}

}  // namespace

Status ReadULog(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits,
                SensorLog* log) {
  *log = SensorLog();
  ULogReader reader(bytes, file_name, limits);
  return reader.Read(log);
}

}  // namespace calibd::server
