// A CDR writer of ROS 2 sensor messages for the tests of formats/mcap.h and
// formats/rosbag2_sqlite.h (plain CDR, alignment from the end of the encapsulation header).
#ifndef CALIBD_TESTS_FORMATS_ROS2_CDR_WRITER_H_
#define CALIBD_TESTS_FORMATS_ROS2_CDR_WRITER_H_

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>

namespace calibd::server::testing {

struct CdrWriter {
  bool big_endian = false;
  std::string body;
  template <typename T>
  void Put(T v) {
    while (body.size() % sizeof(T) != 0) body.push_back('\0');
    char bytes[sizeof(T)];
    std::memcpy(bytes, &v, sizeof(T));
    if (big_endian) std::reverse(bytes, bytes + sizeof(T));
    body.append(bytes, sizeof(T));
  }
  void Header(int32_t sec, uint32_t nsec, const std::string& frame) {
    Put(sec);
    Put(nsec);
    Put(static_cast<uint32_t>(frame.size() + 1));
    body += frame;
    body.push_back('\0');
  }
  std::string Message() const {
    return std::string("\0", 1) + (big_endian ? std::string("\0", 1) : std::string("\1", 1)) +
           std::string(2, '\0') + body;
  }
};

inline std::string ImuCdr(bool big_endian, int32_t sec, uint32_t nsec, const double accel[3],
                          const double gyro[3]) {
  CdrWriter w;
  w.big_endian = big_endian;
  w.Header(sec, nsec, "imu_link");
  for (int i = 0; i < 4; ++i) w.Put(i == 3 ? 1.0 : 0.0);
  for (int i = 0; i < 9; ++i) w.Put(i == 0 ? -1.0 : 0.0);
  for (int i = 0; i < 3; ++i) w.Put(gyro[i]);
  for (int i = 0; i < 9; ++i) w.Put(0.0);
  for (int i = 0; i < 3; ++i) w.Put(accel[i]);
  for (int i = 0; i < 9; ++i) w.Put(0.0);
  return w.Message();
}

inline std::string MagCdr(const double tesla[3]) {
  CdrWriter w;
  w.Header(0, 0, "");
  for (int i = 0; i < 3; ++i) w.Put(tesla[i]);
  for (int i = 0; i < 9; ++i) w.Put(0.0);
  return w.Message();
}

inline std::string TemperatureCdr(int32_t sec, uint32_t nsec, double celsius) {
  CdrWriter w;
  w.Header(sec, nsec, "t");
  w.Put(celsius);
  w.Put(0.0);
  return w.Message();
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_FORMATS_ROS2_CDR_WRITER_H_
