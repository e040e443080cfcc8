// The parsed-columns file (formats/column_file.h).
#include "formats/column_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <utility>
#include <vector>

namespace calibd::server {

using nlohmann::json;

namespace {

constexpr char kMagic[16] = "calibd-columns\n";  // 15 characters and '\0'
constexpr uint32_t kByteOrderMark = 0x01020304;
constexpr uint64_t kMaxHeaderBytes = kMaxColumnFileHeaderBytes;

uint64_t Bits(double x) {
  uint64_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}
double FromBits(uint64_t b) {
  double x;
  std::memcpy(&x, &b, sizeof x);
  return x;
}

// zlib's CRC-32 continued over `data`. An empty block leaves it as it is (zlib would answer a
// null pointer, an empty matrix's data(), with the initial value 0, resetting it).
uint32_t Crc(uint32_t crc, const void* data, size_t n) {
  if (n == 0) return crc;
  return static_cast<uint32_t>(crc32_z(crc, static_cast<const Bytef*>(data), n));
}

json SummaryJson(const RecordingSummary& s) {
  return {{"layout", LayoutName(s.layout)},
          {"rows", s.rows},
          {"columns", s.columns},
          {"sensors", s.sensors},
          {"positions", s.positions},
          {"t_disorder_line", s.t_disorder_line},
          {"t_disorder_column", s.t_disorder_column},
          {"t_disorder", Bits(s.t_disorder)},
          {"t_disorder_previous", Bits(s.t_disorder_previous)},
          {"t_column", s.t_column},
          {"t_first_line", s.t_first_line},
          {"t_first", Bits(s.t_first)},
          {"t_median_step", Bits(s.t_median_step)},
          {"time_origin", s.time_origin},
          {"time_unit", TimeUnitName(s.time_unit)},
          {"format", s.format},
          {"log_description", s.log_description}};
}

// Throws nlohmann's exceptions on a wrong shape (the caller's catch names the file damaged).
RecordingSummary SummaryFromJson(const json& j) {
  RecordingSummary s;
  if (!LayoutFromName(j.at("layout").get<std::string>(), &s.layout) ||
      !TimeUnitFromName(j.at("time_unit").get<std::string>(), &s.time_unit)) {
    throw std::runtime_error("layout or time unit");
  }
  s.rows = j.at("rows").get<int64_t>();
  s.columns = j.at("columns").get<std::vector<std::string>>();
  s.sensors = j.at("sensors").get<std::vector<std::string>>();
  s.positions = j.at("positions").get<int64_t>();
  s.t_disorder_line = j.at("t_disorder_line").get<int64_t>();
  s.t_disorder_column = j.at("t_disorder_column").get<int64_t>();
  s.t_disorder = FromBits(j.at("t_disorder").get<uint64_t>());
  s.t_disorder_previous = FromBits(j.at("t_disorder_previous").get<uint64_t>());
  s.t_column = j.at("t_column").get<int64_t>();
  s.t_first_line = j.at("t_first_line").get<int64_t>();
  s.t_first = FromBits(j.at("t_first").get<uint64_t>());
  s.t_median_step = FromBits(j.at("t_median_step").get<uint64_t>());
  s.time_origin = j.at("time_origin").get<int64_t>();
  s.format = j.at("format").get<std::string>();
  s.log_description = j.at("log_description").get<std::string>();
  return s;
}

// An fd closed on scope exit.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

Status IoError(const std::string& what, const std::string& path) {
  return Status::IoError("column cache: " + what + " " + path + ": " + std::strerror(errno));
}

bool WriteAll(int fd, const void* data, size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t w = ::write(fd, p, std::min<size_t>(n, size_t{1} << 30));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= static_cast<size_t>(w);
  }
  return true;
}

// 0: all read; 1: end of file first (a cut file); -1: error (errno).
int ReadAll(int fd, void* data, size_t n) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    const ssize_t r = ::read(fd, p, std::min<size_t>(n, size_t{1} << 30));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) return -1;
    if (r == 0) return 1;
    p += r;
    n -= static_cast<size_t>(r);
  }
  return 0;
}

// The data matrices in file order.
template <typename Log>
auto Blocks(Log& log) {
  return std::array<std::pair<decltype(log.t.data()), Eigen::Index>, 5>{
      {{log.t.data(), log.t.size()},
       {log.accel.data(), log.accel.size()},
       {log.gyro.data(), log.gyro.size()},
       {log.temperature.data(), log.temperature.size()},
       {log.mag.data(), log.mag.size()}}};
}

Status Damaged(const std::string& path, const std::string& what) {
  return Status(StatusCode::kCorruption, "column cache: " + path + ": " + what);
}

}  // namespace

Status WriteColumnFile(const std::string& path, const ColumnFileKey& key,
                       const RecordingSummary& summary, const ArrayRecording& log, int64_t* bytes) {
  const int64_t n = summary.rows;
  const auto expect = [n](Eigen::Index size, size_t cols) {
    return size == static_cast<Eigen::Index>(n * static_cast<int64_t>(cols));
  };
  if (summary.layout != Layout::kArray || log.accel.rows() != log.gyro.rows() ||
      !(log.t.size() == 0 || log.t.size() == n) ||
      !expect(log.accel.size(), 3 * log.accel_names.size()) ||
      !expect(log.gyro.size(), 3 * log.gyro_names.size()) ||
      !expect(log.temperature.size(), log.temp_names.size()) ||
      !expect(log.mag.size(), 3 * log.mag_names.size())) {
    return Status::Internal("column cache: the log's shape is not its summary's (" +
                            std::to_string(n) + " rows)");
  }
  uint64_t data_bytes = 0;
  for (const auto& [p, size] : Blocks(log)) data_bytes += 8 * static_cast<uint64_t>(size);
  const std::string header = json{
      {"recording_sha256", key.recording_sha256},
      {"rules", key.rules},
      {"summary", SummaryJson(summary)},
      {"has_t", log.t.size() > 0},
      {"accel_names", log.accel_names},
      {"gyro_names", log.gyro_names},
      {"temp_names", log.temp_names},
      {"mag_names", log.mag_names},
      {"mag_device_ids", log.mag_device_ids},
      {"data_bytes", data_bytes}}.dump(-1, ' ', false, json::error_handler_t::replace);
  // The reader refuses a longer header: such an entry would be written only to be rebuilt.
  if (header.size() > kMaxHeaderBytes) {
    return Status(StatusCode::kInvalidInput,
                  "column cache: not written: a header of " + std::to_string(header.size()) +
                      " bytes (names and the log's description) is over the " +
                      std::to_string(kMaxHeaderBytes) + " a reader accepts");
  }
  static std::atomic<uint64_t> counter{0};
  const std::string temporary =
      path + ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter++);
  Fd f;
  f.fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (f.fd < 0) return IoError("cannot create", temporary);
  const uint32_t mark[2] = {kByteOrderMark, kColumnFileVersion};
  const uint64_t header_bytes = header.size();
  const uint32_t header_crc = Crc(0, header.data(), header.size());
  bool ok = WriteAll(f.fd, kMagic, sizeof kMagic) && WriteAll(f.fd, mark, sizeof mark) &&
            WriteAll(f.fd, &header_bytes, sizeof header_bytes) &&
            WriteAll(f.fd, header.data(), header.size()) &&
            WriteAll(f.fd, &header_crc, sizeof header_crc);
  uint32_t data_crc = 0;
  for (const auto& [p, size] : Blocks(log)) {
    if (!ok) break;
    const size_t block = 8 * static_cast<size_t>(size);
    data_crc = Crc(data_crc, p, block);
    ok = WriteAll(f.fd, p, block);
  }
  ok = ok && WriteAll(f.fd, &data_crc, sizeof data_crc) && ::fsync(f.fd) == 0;
  Status s = ok ? Status::Ok() : IoError("cannot write", temporary);
  if (s.ok() && ::close(f.fd) != 0) s = IoError("cannot close", temporary);
  f.fd = -1;
  if (s.ok() && ::rename(temporary.c_str(), path.c_str()) != 0) s = IoError("cannot rename", path);
  if (!s.ok()) {
    ::unlink(temporary.c_str());
    return s;
  }
  // The rename itself made durable (a crash before this leaves the old entry or none).
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "." : path.substr(0, slash + 1);
  Fd d;
  d.fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (d.fd >= 0) (void)::fsync(d.fd);
  if (bytes != nullptr) {
    *bytes = static_cast<int64_t>(sizeof kMagic + sizeof mark + sizeof header_bytes +
                                  header.size() + 4 + data_bytes + 4);
  }
  return Status::Ok();
}

Status ReadColumnFile(const std::string& path, const ColumnFileKey& expected,
                      RecordingSummary* summary, ArrayRecording* out) {
  Fd f;
  f.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f.fd < 0) {
    if (errno == ENOENT) return Status::NotFound("column cache: no " + path);
    return IoError("cannot open", path);
  }
  struct stat st;
  if (::fstat(f.fd, &st) != 0) return IoError("cannot stat", path);
  const uint64_t size = static_cast<uint64_t>(st.st_size);
  char magic[sizeof kMagic];
  uint32_t mark[2];
  uint64_t header_bytes = 0;
  int r = ReadAll(f.fd, magic, sizeof magic);
  if (r == 0) r = ReadAll(f.fd, mark, sizeof mark);
  if (r == 0) r = ReadAll(f.fd, &header_bytes, sizeof header_bytes);
  if (r < 0) return IoError("cannot read", path);
  if (r > 0) return Damaged(path, "cut short in its first 32 bytes");
  if (std::memcmp(magic, kMagic, sizeof kMagic) != 0) return Damaged(path, "not a column file");
  if (mark[0] != kByteOrderMark) return Damaged(path, "written with another byte order");
  if (mark[1] != kColumnFileVersion) {
    return Damaged(
        path, "version " + std::to_string(mark[1]) + ", not " + std::to_string(kColumnFileVersion));
  }
  const uint64_t fixed = sizeof magic + sizeof mark + sizeof header_bytes + 4 + 4;
  if (header_bytes > kMaxHeaderBytes || fixed + header_bytes > size) {
    return Damaged(path, "header of " + std::to_string(header_bytes) + " bytes in a file of " +
                             std::to_string(size));
  }
  std::string header(header_bytes, '\0');
  uint32_t header_crc = 0;
  r = ReadAll(f.fd, header.data(), header.size());
  if (r == 0) r = ReadAll(f.fd, &header_crc, sizeof header_crc);
  if (r < 0) return IoError("cannot read", path);
  if (r > 0) return Damaged(path, "cut short in its header");
  if (Crc(0, header.data(), header.size()) != header_crc) {
    return Damaged(path, "the header's checksum does not match");
  }
  ArrayRecording log;
  RecordingSummary s;
  uint64_t data_bytes = 0;
  bool has_t = false;
  try {
    const json h = json::parse(header);
    if (h.at("recording_sha256").get<std::string>() != expected.recording_sha256 ||
        h.at("rules").get<std::string>() != expected.rules) {
      return Damaged(path, "written for other bytes or reading rules");
    }
    s = SummaryFromJson(h.at("summary"));
    has_t = h.at("has_t").get<bool>();
    log.accel_names = h.at("accel_names").get<std::vector<std::string>>();
    log.gyro_names = h.at("gyro_names").get<std::vector<std::string>>();
    log.temp_names = h.at("temp_names").get<std::vector<std::string>>();
    log.mag_names = h.at("mag_names").get<std::vector<std::string>>();
    log.mag_device_ids = h.at("mag_device_ids").get<std::vector<int64_t>>();
    data_bytes = h.at("data_bytes").get<uint64_t>();
  } catch (const std::exception& e) {
    return Damaged(path, std::string("its header does not read: ") + e.what());
  }
  const uint64_t n = static_cast<uint64_t>(s.rows);
  const uint64_t columns = (has_t ? 1 : 0) + 3 * log.accel_names.size() +
                           3 * log.gyro_names.size() + log.temp_names.size() +
                           3 * log.mag_names.size();
  if (s.rows < 0 || s.layout != Layout::kArray || columns == 0 || n > data_bytes / 8 / columns ||
      8 * n * columns != data_bytes || fixed + header_bytes + data_bytes != size) {
    return Damaged(path, std::to_string(size) + " bytes, not what its header describes (" +
                             std::to_string(n) + " rows of " + std::to_string(columns) +
                             " columns): cut or overwritten");
  }
  const auto rows = static_cast<Eigen::Index>(n);
  log.t.resize(has_t ? rows : 0);
  log.accel.resize(rows, static_cast<Eigen::Index>(3 * log.accel_names.size()));
  log.gyro.resize(rows, static_cast<Eigen::Index>(3 * log.gyro_names.size()));
  log.temperature.resize(rows, static_cast<Eigen::Index>(log.temp_names.size()));
  log.mag.resize(rows, static_cast<Eigen::Index>(3 * log.mag_names.size()));
  uint32_t crc = 0;
  for (const auto& [p, count] : Blocks(log)) {
    const size_t block = 8 * static_cast<size_t>(count);
    r = ReadAll(f.fd, p, block);
    if (r < 0) return IoError("cannot read", path);
    if (r > 0) return Damaged(path, "cut short in its data");
    crc = Crc(crc, p, block);
  }
  uint32_t data_crc = 0;
  r = ReadAll(f.fd, &data_crc, sizeof data_crc);
  if (r < 0) return IoError("cannot read", path);
  if (r > 0) return Damaged(path, "cut short at its data checksum");
  if (crc != data_crc) return Damaged(path, "the data's checksum does not match");
  *summary = std::move(s);
  *out = std::move(log);
  return Status::Ok();
}

}  // namespace calibd::server
