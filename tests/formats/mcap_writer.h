// An MCAP writer of the ROS 2 records calibd reads (formats/mcap.h), for tests: records, ros2msg
// schemas, cdr channels, messages (publish time = log time) and chunks (uncompressed, lz4, zstd).
// Layout of a file: McapBegin() + records or Chunk(records) + McapEnd().
#ifndef CALIBD_TESTS_FORMATS_MCAP_WRITER_H_
#define CALIBD_TESTS_FORMATS_MCAP_WRITER_H_

#include <lz4frame.h>
#include <zstd.h>

#include <cstdint>
#include <string>

namespace calibd::server::testing {

template <typename T>
inline void Put(T v, std::string* out) {
  out->append(reinterpret_cast<const char*>(&v), sizeof(T));
}
inline void PutString(const std::string& s, std::string* out) {
  Put(static_cast<uint32_t>(s.size()), out);
  *out += s;
}
inline std::string Record(uint8_t op, const std::string& content) {
  std::string r(1, static_cast<char>(op));
  Put(static_cast<uint64_t>(content.size()), &r);
  return r + content;
}
inline std::string Schema(uint16_t id, const std::string& name) {
  std::string c;
  Put(id, &c);
  PutString(name, &c);
  PutString("ros2msg", &c);
  PutString("", &c);
  return Record(0x03, c);
}
inline std::string Channel(uint16_t id, uint16_t schema, const std::string& topic) {
  std::string c;
  Put(id, &c);
  Put(schema, &c);
  PutString(topic, &c);
  PutString("cdr", &c);
  Put(uint32_t{0}, &c);  // metadata: empty map
  return Record(0x04, c);
}
inline std::string Message(uint16_t channel, uint64_t log_time, const std::string& data) {
  std::string c;
  Put(channel, &c);
  Put(uint32_t{0}, &c);
  Put(log_time, &c);
  Put(log_time, &c);
  return Record(0x05, c + data);
}
inline std::string Chunk(const std::string& records, const std::string& compression) {
  std::string stored = records;
  if (compression == "lz4") {
    stored.resize(LZ4F_compressFrameBound(records.size(), nullptr));
    stored.resize(
        LZ4F_compressFrame(stored.data(), stored.size(), records.data(), records.size(), nullptr));
  } else if (compression == "zstd") {
    stored.resize(ZSTD_compressBound(records.size()));
    stored.resize(ZSTD_compress(stored.data(), stored.size(), records.data(), records.size(), 3));
  }
  std::string c;
  Put(uint64_t{0}, &c);
  Put(uint64_t{0}, &c);
  Put(static_cast<uint64_t>(records.size()), &c);
  Put(uint32_t{0}, &c);
  PutString(compression, &c);
  Put(static_cast<uint64_t>(stored.size()), &c);
  return Record(0x06, c + stored);
}

inline const std::string kMcapMagic("\x89MCAP0\r\n", 8);

// The magic and an empty Header record.
inline std::string McapBegin() { return kMcapMagic + Record(0x01, std::string(8, '\0')); }
// An empty DataEnd, an empty Footer and the closing magic.
inline std::string McapEnd() {
  return Record(0x0F, std::string(4, '\0')) + Record(0x02, std::string(20, '\0')) + kMcapMagic;
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_FORMATS_MCAP_WRITER_H_
