// MCAP (mcap.dev/spec): the ROS 2 sensor_msgs Imu, MagneticField and Temperature messages of an
// MCAP file, CDR-encoded (channel message_encoding "cdr", schema name "sensor_msgs/msg/Imu", ...),
// as a SensorLog (formats/sensor_log.h, format "mcap"; SPEC §9).
//
// The data section is read in file order: records at top level and inside chunks (uncompressed,
// "lz4" frame or "zstd", each decompressed to its stated uncompressed_size, all together within
// SensorLogLimits::max_decompressed_bytes), up to DataEnd or the Footer; the summary section and
// indexes are not needed, so a file whose writer stopped before its summary reads too (with a
// warning). Unknown opcodes are skipped, as the specification asks. Record time is the message's
// log_time; the chunks' CRCs are not checked (the lengths and decompressed sizes are).
// A file cut inside a record reads up to the last whole top-level record with a warning naming
// the byte offset; damage (a record length past 2^48, a chunk that does not decompress to its
// size, a record overrunning its chunk, a message before its channel, a message too short for its
// type) is kInvalidInput naming the byte offset.
#ifndef CALIBD_FORMATS_MCAP_H_
#define CALIBD_FORMATS_MCAP_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Reads the MCAP file `bytes` (borrowed for the call) into `*log` (replaced). `file_name` names
// the file in messages. Stateless, thread-safe.
Status ReadMcap(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits,
                SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_MCAP_H_
