// CDR decoding of ROS 2 sensor messages (formats/cdr.h).
#include "formats/cdr.h"

#include <cstdint>
#include <cstring>
#include <utility>

namespace calibd::server {
namespace {

// Reads aligned CDR primitives after the encapsulation header; `ok` turns false past the end.
struct CdrCursor {
  std::string_view b;  // the message after its 4-byte encapsulation header
  bool big_endian = false;
  size_t pos = 0;
  bool ok = true;

  bool Take(size_t n, void* out) {
    size_t aligned = (pos + n - 1) / n * n;
    ok = ok && aligned <= b.size() && n <= b.size() - aligned;
    if (!ok) return false;
    unsigned char bytes[8];
    std::memcpy(bytes, b.data() + aligned, n);
    if (big_endian) {
      for (size_t i = 0; i < n / 2; ++i) std::swap(bytes[i], bytes[n - 1 - i]);
    }
    std::memcpy(out, bytes, n);
    pos = aligned + n;
    return true;
  }
  uint32_t U32() {
    uint32_t v = 0;
    Take(4, &v);
    return v;
  }
  double F64() {
    double v = 0;
    Take(8, &v);
    return v;
  }
  void F64s(double* out, int n) {
    for (int i = 0; i < n; ++i) out[i] = F64();
  }
  // std_msgs/msg/Header: stamp (int32 sec, uint32 nanosec), string frame_id. The stamp in ns.
  int64_t Header() {
    int64_t sec = static_cast<int32_t>(U32());
    int64_t nsec = U32();
    uint32_t len = U32();  // with its terminating NUL
    ok = ok && len <= b.size() - pos;
    if (ok) pos += len;
    return sec * 1'000'000'000 + nsec;
  }
};

}  // namespace

RosMessageType Ros2MessageType(std::string_view type_name) {
  if (type_name == "sensor_msgs/msg/Imu") return RosMessageType::kImu;
  if (type_name == "sensor_msgs/msg/MagneticField") return RosMessageType::kMagneticField;
  if (type_name == "sensor_msgs/msg/Temperature") return RosMessageType::kTemperature;
  return RosMessageType::kOther;
}

bool DecodeCdrMessage(std::string_view data, RosMessageType type, RosSample* s) {
  // Encapsulation: 0x00 0x00 plain CDR big-endian, 0x00 0x01 little-endian; then 2 option bytes.
  if (data.size() < 4 || data[0] != 0 || (data[1] != 0 && data[1] != 1)) return false;
  CdrCursor c{data.substr(4), data[1] == 0};
  s->stamp_ns = c.Header();
  return ReadSensorFields(c, type, s);
}

}  // namespace calibd::server
