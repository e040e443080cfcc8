// ROS 1 bags (format 2.0, "#ROSBAG V2.0"): the sensor_msgs Imu, MagneticField and Temperature
// messages of a bag as a SensorLog (formats/sensor_log.h; SPEC §9).
//
// The reader follows the published format (wiki.ros.org/Bags/Format/2.0): records of a header
// (fields name=value, `op` the record type) and data; chunks uncompressed, bz2 or lz4 (the LZ4
// frame format), each decompressed to its stated size, all of them together within
// SensorLogLimits::max_decompressed_bytes. The index records are not needed (the chunks are read
// in file order), so a bag left unindexed (a recorder killed) reads too. Messages are decoded
// from their ROS 1 serialization when the connection's type and md5sum are those of
// sensor_msgs/Imu, MagneticField or Temperature; other topics are skipped.
// A bag cut inside a record reads up to the last whole record before it, with a warning naming
// the byte offset; damage (an impossible length, a chunk that does not decompress to its stated
// size, an unknown op, a message too short for its type) is kInvalidInput naming the byte offset
// (the offset of the chunk, and the offset inside the decompressed chunk).
#ifndef CALIBD_FORMATS_ROSBAG1_H_
#define CALIBD_FORMATS_ROSBAG1_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Reads the bag `bytes` (the whole file, borrowed for the call) into `*log` (replaced; format
// "rosbag1"). `file_name` names the file in messages. Stateless, thread-safe.
Status ReadRosBag1(std::string_view bytes, const std::string& file_name,
                   const SensorLogLimits& limits, SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_ROSBAG1_H_
