// MCAP reader (formats/mcap.h).
#include "formats/mcap.h"

#include <cstdint>
#include <cstring>
#include <map>
#include <utility>

#include "formats/cdr.h"
#include "formats/chunk_codec.h"
#include "formats/ros_topics.h"

namespace calibd::server {
namespace {

constexpr std::string_view kMagic("\x89MCAP0\r\n", 8);
// Opcodes (mcap.dev/spec).
constexpr uint8_t kOpFooter = 0x02;
constexpr uint8_t kOpSchema = 0x03;
constexpr uint8_t kOpChannel = 0x04;
constexpr uint8_t kOpMessage = 0x05;
constexpr uint8_t kOpChunk = 0x06;
constexpr uint8_t kOpDataEnd = 0x0F;
constexpr uint64_t kMaxRecordLength = uint64_t{1} << 48;

// Little-endian fields of one record's content; `ok` turns false past its end.
struct Fields {
  std::string_view b;
  size_t pos = 0;
  bool ok = true;
  template <typename T>
  T Int() {
    T v = 0;
    ok = ok && sizeof(T) <= b.size() - pos;
    if (!ok) return 0;
    std::memcpy(&v, b.data() + pos, sizeof(T));  // little-endian hosts (CMake checks)
    pos += sizeof(T);
    return v;
  }
  std::string_view Bytes(uint64_t n) {
    ok = ok && n <= b.size() - pos;
    if (!ok) return {};
    std::string_view v = b.substr(pos, n);
    pos += n;
    return v;
  }
  std::string_view String() { return Bytes(Int<uint32_t>()); }
  std::string_view Rest() { return ok ? b.substr(pos) : std::string_view(); }
};

struct Channel {
  std::string topic;
  RosMessageType type = RosMessageType::kOther;
};

class McapReader {
 public:
  McapReader(const std::string& file_name, const SensorLogLimits& limits, SensorLog* log)
      : file_name_(file_name), limits_(limits), samples_(limits), log_(log) {}

  // Reads the records of `data`: the file after the magic (chunk_offset < 0) or one decompressed
  // chunk, the chunk record at file byte chunk_offset. `base` is data's offset in its container.
  Status ReadRecords(std::string_view data, int64_t base, int64_t chunk_offset);
  void Finish() { samples_.Finish(log_); }

 private:
  Status Damage(int64_t offset, int64_t chunk_offset, const std::string& what) const;
  Status ReadRecord(uint8_t op, std::string_view content, int64_t offset, int64_t chunk_offset);
  Status ReadChunk(std::string_view content, int64_t offset);

  const std::string& file_name_;
  SensorLogLimits limits_;
  RosTopicSamples samples_;
  SensorLog* log_;
  std::map<uint16_t, std::string> schemas_;  // id -> name
  std::map<uint16_t, Channel> channels_;
  int64_t decompressed_ = 0;
  bool ended_ = false;  // DataEnd or Footer read
};

Status McapReader::Damage(int64_t offset, int64_t chunk_offset, const std::string& what) const {
  std::string where = "at byte " + std::to_string(offset);
  if (chunk_offset >= 0) where += " of the chunk at byte " + std::to_string(chunk_offset);
  return Status::InvalidInput(file_name_ + ": damaged MCAP file: " + what + " " + where)
      .WithFile(file_name_);
}

Status McapReader::ReadRecords(std::string_view data, int64_t base, int64_t chunk_offset) {
  size_t pos = 0;
  while (pos < data.size() && !ended_) {
    const int64_t offset = base + static_cast<int64_t>(pos);
    const size_t left = data.size() - pos;
    uint64_t length = 0;
    if (left >= 9) std::memcpy(&length, data.data() + pos + 1, 8);
    if (length >= kMaxRecordLength) {
      return Damage(offset, chunk_offset, "a record length of " + std::to_string(length));
    }
    if (left < 9 || length > left - 9) {
      if (chunk_offset >= 0) return Damage(offset, chunk_offset, "a record overruns its chunk");
      log_->warnings.push_back(
          "MCAP file cut at byte " + std::to_string(offset) +
          " in the middle of a record (a recorder stopped?): read up to there");
      return Status::Ok();
    }
    Status s = ReadRecord(static_cast<uint8_t>(data[pos]), data.substr(pos + 9, length), offset,
                          chunk_offset);
    if (!s.ok()) return s;
    pos += 9 + length;
  }
  if (chunk_offset < 0 && !ended_) {
    log_->warnings.push_back("MCAP file ends at byte " + std::to_string(base + pos) +
                             " without its footer (a recorder stopped?): read up to there");
  }
  return Status::Ok();
}

Status McapReader::ReadRecord(uint8_t op, std::string_view content, int64_t offset,
                              int64_t chunk_offset) {
  Fields f{content};
  switch (op) {
    case kOpFooter:
    case kOpDataEnd:
      if (chunk_offset < 0) ended_ = true;
      return Status::Ok();
    case kOpChunk:
      if (chunk_offset >= 0) return Damage(offset, chunk_offset, "a chunk inside a chunk");
      return ReadChunk(content, offset);
    case kOpSchema: {
      uint16_t id = f.Int<uint16_t>();
      std::string_view name = f.String();
      if (!f.ok) return Damage(offset, chunk_offset, "a schema record too short");
      schemas_[id] = std::string(name);
      return Status::Ok();
    }
    case kOpChannel: {
      uint16_t id = f.Int<uint16_t>();
      uint16_t schema_id = f.Int<uint16_t>();
      std::string_view topic = f.String();
      std::string_view encoding = f.String();
      if (!f.ok) return Damage(offset, chunk_offset, "a channel record too short");
      auto schema = schemas_.find(schema_id);
      if (schema_id != 0 && schema == schemas_.end()) {
        return Damage(offset, chunk_offset, "a channel before its schema record");
      }
      Channel c;
      c.topic = std::string(topic);
      if (schema_id != 0 && encoding == "cdr") c.type = Ros2MessageType(schema->second);
      channels_[id] = std::move(c);
      return Status::Ok();
    }
    case kOpMessage: {
      uint16_t channel_id = f.Int<uint16_t>();
      f.Int<uint32_t>();  // sequence
      uint64_t log_time = f.Int<uint64_t>();
      f.Int<uint64_t>();  // publish_time
      if (!f.ok) return Damage(offset, chunk_offset, "a message record too short");
      auto c = channels_.find(channel_id);
      if (c == channels_.end()) {
        return Damage(offset, chunk_offset, "a message before its channel record");
      }
      if (c->second.type == RosMessageType::kOther) return Status::Ok();
      RosSample sample;
      sample.record_ns = static_cast<int64_t>(log_time);
      if (!DecodeCdrMessage(f.Rest(), c->second.type, &sample)) {
        return Damage(offset, chunk_offset, "a message not CDR or too short for its type");
      }
      Status s = samples_.Add(c->second.topic, c->second.type, sample);
      return s.ok() ? s : s.WithFile(file_name_);
    }
    default:
      return Status::Ok();  // header, indexes, attachments, metadata, statistics, unknown ops
  }
}

Status McapReader::ReadChunk(std::string_view content, int64_t offset) {
  Fields f{content};
  f.Int<uint64_t>();  // message_start_time
  f.Int<uint64_t>();  // message_end_time
  uint64_t size = f.Int<uint64_t>();
  f.Int<uint32_t>();  // uncompressed_crc
  std::string_view compression = f.String();
  std::string_view records = f.Bytes(f.Int<uint64_t>());
  if (!f.ok) return Damage(offset, -1, "a chunk record too short");
  if (size > static_cast<uint64_t>(limits_.max_decompressed_bytes - decompressed_)) {
    return Status::InvalidInput(file_name_ + ": the chunks decompress to more than " +
                                std::to_string(limits_.max_decompressed_bytes) +
                                " bytes (max_decompressed_bytes)")
        .WithFile(file_name_);
  }
  decompressed_ += static_cast<int64_t>(size);
  std::string buffer;
  if (compression.empty()) {
    if (records.size() != size) {
      return Damage(offset, -1, "an uncompressed chunk whose size is not its stated size");
    }
  } else {
    ChunkCodec codec;
    if (compression == "lz4") {
      codec = ChunkCodec::kLz4Frame;
    } else if (compression == "zstd") {
      codec = ChunkCodec::kZstd;
    } else {
      return Damage(offset, -1,
                    "a chunk compressed with unknown \"" + std::string(compression) + "\"");
    }
    if (!DecompressExactly(codec, records, size, &buffer)) {
      return Damage(offset, -1,
                    "a " + std::string(compression) + " chunk that does not decompress to its " +
                        "stated size of " + std::to_string(size) + " bytes");
    }
    records = buffer;
  }
  return ReadRecords(records, 0, offset);
}

}  // namespace

Status ReadMcap(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits,
                SensorLog* log) {
  *log = SensorLog();
  log->format = "mcap";
  if (bytes.substr(0, kMagic.size()) != kMagic) {
    return Status::InvalidInput(file_name + ": not an MCAP file (no MCAP magic)")
        .WithFile(file_name);
  }
  McapReader reader(file_name, limits, log);
  Status s = reader.ReadRecords(bytes.substr(kMagic.size()), kMagic.size(), -1);
  if (!s.ok()) {
    *log = SensorLog();
    return s;
  }
  reader.Finish();
  return Status::Ok();
}

}  // namespace calibd::server
