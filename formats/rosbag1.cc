// ROS 1 bag 2.0 reader (formats/rosbag1.h).
#include "formats/rosbag1.h"

#include <algorithm>
#include <cstring>
#include <map>
#include <memory>
#include <utility>

#include "formats/chunk_codec.h"
#include "formats/ros_topics.h"

namespace calibd::server {
namespace {

constexpr std::string_view kMagic = "#ROSBAG V2.0\n";
// Record ops (wiki.ros.org/Bags/Format/2.0).
constexpr uint8_t kOpMessageData = 0x02;
constexpr uint8_t kOpBagHeader = 0x03;
constexpr uint8_t kOpIndexData = 0x04;
constexpr uint8_t kOpChunk = 0x05;
constexpr uint8_t kOpChunkInfo = 0x06;
constexpr uint8_t kOpConnection = 0x07;

uint32_t U32(std::string_view b, size_t pos) {
  uint32_t v;
  std::memcpy(&v, b.data() + pos, 4);  // little-endian hosts (CMake checks)
  return v;
}

// The fields of a record header (or of a connection header): name -> value, borrowed.
using Fields = std::map<std::string_view, std::string_view>;

// Parses `header` into `*fields`; false when a field's length overruns or it has no '='.
bool ParseFields(std::string_view header, Fields* fields) {
  size_t pos = 0;
  while (pos < header.size()) {
    if (header.size() - pos < 4) return false;
    uint32_t len = U32(header, pos);
    pos += 4;
    if (len > header.size() - pos) return false;
    std::string_view field = header.substr(pos, len);
    size_t eq = field.find('=');
    if (eq == std::string_view::npos) return false;
    (*fields)[field.substr(0, eq)] = field.substr(eq + 1);
    pos += len;
  }
  return true;
}

// The message types read, by ROS 1 type name and md5sum.
struct KnownType {
  const char* name;
  const char* md5;
  RosMessageType type;
};
constexpr KnownType kKnownTypes[] = {
    {"sensor_msgs/Imu", "6a62c6daae103f4ff57a132d6f95cec2", RosMessageType::kImu},
    {"sensor_msgs/MagneticField", "2f3b0b43eed0c9501de0fa3ff89a45aa",
     RosMessageType::kMagneticField},
    {"sensor_msgs/Temperature", "ff71b307acdbe7c871a5a6d7ed359100", RosMessageType::kTemperature},
};

// Reads little-endian ROS 1 serialized fields; `ok` turns false past the end.
struct MessageCursor {
  std::string_view b;
  size_t pos = 0;
  bool ok = true;
  bool Need(size_t n) {
    ok = ok && n <= b.size() - pos;
    return ok;
  }
  uint32_t U32() {
    if (!Need(4)) return 0;
    uint32_t v = calibd::server::U32(b, pos);
    pos += 4;
    return v;
  }
  double F64() {
    double v = 0;
    if (!Need(8)) return 0;
    std::memcpy(&v, b.data() + pos, 8);
    pos += 8;
    return v;
  }
  void F64s(double* out, int n) {
    for (int i = 0; i < n; ++i) out[i] = F64();
  }
  void Skip(size_t n) {
    if (Need(n)) pos += n;
  }
  // std_msgs/Header: seq, stamp (sec, nsec), frame_id. Returns the stamp in ns.
  int64_t Header() {
    U32();
    int64_t sec = U32();
    int64_t nsec = U32();
    Skip(U32());
    return sec * 1'000'000'000 + nsec;
  }
};

// Decodes one ROS 1 message of `type`; false when it is too short.
bool DecodeMessage(std::string_view data, RosMessageType type, RosSample* s) {
  MessageCursor c{data};
  s->stamp_ns = c.Header();
  ReadSensorFields(c, type, s);  // kOther: the header alone
  return c.ok;
}

struct Connection {
  std::string topic;
  RosMessageType type = RosMessageType::kOther;
};

class BagReader {
 public:
  BagReader(const std::string& file_name, const SensorLogLimits& limits, SensorLog* log)
      : file_name_(file_name), limits_(limits), samples_(limits), log_(log) {}

  // Reads the records of `data`: the file after the magic (chunk_offset < 0) or one decompressed
  // chunk, the chunk record at file byte chunk_offset. `base` is data's offset in its container.
  Status ReadRecords(std::string_view data, int64_t base, int64_t chunk_offset);
  void Finish() { samples_.Finish(log_); }

 private:
  Status Damage(int64_t offset, int64_t chunk_offset, const std::string& what) const;
  Status ReadRecord(uint8_t op, const Fields& header, std::string_view data, int64_t offset,
                    int64_t chunk_offset);
  Status ReadConnection(const Fields& header, std::string_view data, int64_t offset,
                        int64_t chunk_offset);
  Status ReadChunk(const Fields& header, std::string_view data, int64_t offset);
  Status Decompress(std::string_view compression, std::string_view in, uint32_t size,
                    int64_t offset, std::string* out);

  const std::string& file_name_;
  SensorLogLimits limits_;
  RosTopicSamples samples_;
  SensorLog* log_;
  std::map<uint32_t, Connection> connections_;
  int64_t decompressed_ = 0;
};

Status BagReader::Damage(int64_t offset, int64_t chunk_offset, const std::string& what) const {
  std::string where = chunk_offset < 0
                          ? "at byte " + std::to_string(offset)
                          : "at byte " + std::to_string(offset) + " of the chunk at byte " +
                                std::to_string(chunk_offset);
  return Status::InvalidInput(file_name_ + ": damaged ROS bag: " + what + " " + where)
      .WithFile(file_name_);
}

Status BagReader::ReadRecords(std::string_view data, int64_t base, int64_t chunk_offset) {
  size_t pos = 0;
  while (pos < data.size()) {
    const int64_t offset = base + static_cast<int64_t>(pos);
    const size_t left = data.size() - pos;
    uint32_t header_len = left >= 4 ? U32(data, pos) : 0;
    uint32_t data_len = 0;
    if (left >= 4 && header_len > 0x7fffffffu) {
      return Damage(offset, chunk_offset,
                    "a record header length of " + std::to_string(header_len) + " bytes");
    }
    bool whole = left >= 8 && header_len <= left - 8;
    if (whole) {
      data_len = U32(data, pos + 4 + header_len);
      whole = data_len <= left - 8 - header_len;
    }
    if (!whole) {
      if (chunk_offset >= 0) return Damage(offset, chunk_offset, "a record overruns its chunk");
      log_->warnings.push_back(
          "bag cut at byte " + std::to_string(offset) +
          " in the middle of a record (a recorder stopped?): read up to there");
      return Status::Ok();
    }
    Fields header;
    if (!ParseFields(data.substr(pos + 4, header_len), &header)) {
      return Damage(offset, chunk_offset, "a record header whose fields overrun it");
    }
    auto op = header.find("op");
    if (op == header.end() || op->second.size() != 1) {
      return Damage(offset, chunk_offset, "a record without a one-byte op");
    }
    Status s = ReadRecord(static_cast<uint8_t>(op->second[0]), header,
                          data.substr(pos + 8 + header_len, data_len), offset, chunk_offset);
    if (!s.ok()) return s;
    pos += 8 + size_t{header_len} + data_len;
  }
  return Status::Ok();
}

Status BagReader::ReadRecord(uint8_t op, const Fields& header, std::string_view data,
                             int64_t offset, int64_t chunk_offset) {
  switch (op) {
    case kOpBagHeader:
    case kOpIndexData:
    case kOpChunkInfo:
      return Status::Ok();  // the index: not needed, the chunks are read in order
    case kOpChunk:
      if (chunk_offset >= 0) return Damage(offset, chunk_offset, "a chunk inside a chunk");
      return ReadChunk(header, data, offset);
    case kOpConnection:
      return ReadConnection(header, data, offset, chunk_offset);
    case kOpMessageData: {
      auto conn = header.find("conn");
      auto time = header.find("time");
      if (conn == header.end() || conn->second.size() != 4 || time == header.end() ||
          time->second.size() != 8) {
        return Damage(offset, chunk_offset, "a message record without conn or time");
      }
      auto c = connections_.find(U32(conn->second, 0));
      if (c == connections_.end()) {
        return Damage(offset, chunk_offset, "a message before its connection record");
      }
      if (c->second.type == RosMessageType::kOther) return Status::Ok();
      RosSample sample;
      sample.record_ns = int64_t{U32(time->second, 0)} * 1'000'000'000 + U32(time->second, 4);
      if (!DecodeMessage(data, c->second.type, &sample)) {
        return Damage(offset, chunk_offset, "a message too short for its type");
      }
      Status s = samples_.Add(c->second.topic, c->second.type, sample);
      return s.ok() ? s : s.WithFile(file_name_);
    }
    default:
      return Damage(offset, chunk_offset, "an unknown op " + std::to_string(op));
  }
}

Status BagReader::ReadConnection(const Fields& header, std::string_view data, int64_t offset,
                                 int64_t chunk_offset) {
  auto conn = header.find("conn");
  auto topic = header.find("topic");
  Fields conn_header;
  if (conn == header.end() || conn->second.size() != 4 || topic == header.end() ||
      !ParseFields(data, &conn_header)) {
    return Damage(offset, chunk_offset, "a connection record without conn, topic or header");
  }
  // The index section repeats the connections of the chunks: the first record of an id holds.
  if (connections_.count(U32(conn->second, 0)) != 0) return Status::Ok();
  Connection c;
  c.topic = std::string(topic->second);
  std::string_view type = conn_header["type"];
  for (const KnownType& known : kKnownTypes) {
    if (type != known.name) continue;
    if (conn_header["md5sum"] == known.md5) {
      c.type = known.type;
    } else {
      log_->warnings.push_back("topic " + c.topic + " has type " + std::string(type) +
                               " with md5sum " + std::string(conn_header["md5sum"]) +
                               ", not the layout calibd reads: skipped");
    }
  }
  connections_[U32(conn->second, 0)] = std::move(c);
  return Status::Ok();
}

Status BagReader::ReadChunk(const Fields& header, std::string_view data, int64_t offset) {
  auto compression = header.find("compression");
  auto size = header.find("size");
  if (compression == header.end() || size == header.end() || size->second.size() != 4) {
    return Damage(offset, -1, "a chunk without compression or size");
  }
  std::string buffer;
  std::string_view records = data;
  if (compression->second != "none") {
    Status s = Decompress(compression->second, data, U32(size->second, 0), offset, &buffer);
    if (!s.ok()) return s;
    records = buffer;
  } else if (data.size() != U32(size->second, 0)) {
    return Damage(offset, -1, "an uncompressed chunk whose size is not its stated size");
  }
  return ReadRecords(records, 0, offset);
}

Status BagReader::Decompress(std::string_view compression, std::string_view in, uint32_t size,
                             int64_t offset, std::string* out) {
  decompressed_ += size;
  if (decompressed_ > limits_.max_decompressed_bytes) {
    return Status::InvalidInput(file_name_ + ": the chunks decompress to more than " +
                                std::to_string(limits_.max_decompressed_bytes) +
                                " bytes (max_decompressed_bytes)")
        .WithFile(file_name_);
  }
  ChunkCodec codec;
  if (compression == "bz2") {
    codec = ChunkCodec::kBz2;
  } else if (compression == "lz4") {
    codec = ChunkCodec::kLz4Frame;
  } else {
    return Damage(offset, -1,
                  "a chunk compressed with unknown \"" + std::string(compression) + "\"");
  }
  if (!DecompressExactly(codec, in, size, out)) {
    return Damage(offset, -1,
                  "a " + std::string(compression) + " chunk that does not decompress to its " +
                      "stated size of " + std::to_string(size) + " bytes");
  }
  return Status::Ok();
}

}  // namespace

Status ReadRosBag1(std::string_view bytes, const std::string& file_name,
                   const SensorLogLimits& limits, SensorLog* log) {
  *log = SensorLog();
  log->format = "rosbag1";
  if (bytes.substr(0, kMagic.size()) != kMagic) {
    return Status::InvalidInput(file_name + ": not a ROS bag 2.0 (no \"#ROSBAG V2.0\" line)")
        .WithFile(file_name);
  }
  BagReader reader(file_name, limits, log);
  Status s = reader.ReadRecords(bytes.substr(kMagic.size()), kMagic.size(), -1);
  if (!s.ok()) {
    *log = SensorLog();
    return s;
  }
  reader.Finish();
  return Status::Ok();
}

}  // namespace calibd::server
