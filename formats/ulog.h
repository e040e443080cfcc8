// PX4 ULog (.ulg) reader (SPEC §9), written from the published format (PX4 dev guide, "ULog
// File Format"): a 16-byte header ("ULog" 01 12 35, version, µs timestamp), then messages of a
// 3-byte header (uint16 payload size, uint8 type) and a little-endian packed payload. Read:
// 'B' flag bits (first; unknown incompatible flags refused; appended-data offsets followed),
// 'F' formats (nested types, arrays, `_padding` fields), 'I'/'M'/'P'/'Q' (checked, not kept),
// 'A'/'R' subscriptions (multi_id), 'D' data, 'L'/'C' log text, 'S' sync, 'O' dropouts; other
// types are skipped as the format asks.
//
// Streams produced (formats/sensor_log.h), per kind from the best source the log holds:
//   accel: sensor_accel_fifo, else sensor_accel, else sensor_combined (accelerometer_m_s2);
//   gyro:  sensor_gyro_fifo, else sensor_gyro, else sensor_combined (gyro_rad);
//   mag:   sensor_mag (gauss → µT);
//   temperature: the `temperature` field of every sensor_accel*, sensor_gyro*, sensor_mag topic
//     that has one (same topic and instance; samples that are not finite, PX4's "no sensor",
//     are left out).
// A fifo message is a burst of `samples` readings x[i]·scale (int16) `dt` µs apart, the last at
// the message's time. sensor_accel/sensor_gyro streams logged at 50 Hz or slower and
// sensor_combined streams carry a note. instance = multi_id; device_id from the message (the
// first message's), -1 for sensor_combined. Time: `timestamp_sample` when the format has it and
// it is non-zero in every message of the stream, else `timestamp` (µs → ns, exact).
#ifndef CALIBD_FORMATS_ULOG_H_
#define CALIBD_FORMATS_ULOG_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Reads the ULog `bytes` (the whole file; not kept) into *log (format "ulog"; replaced). A log
// cut inside a message reads to the last whole message with a warning naming the byte offset.
// Damage (a payload too short for its type, a 'D' larger than its format or for a msg_id not
// subscribed, an undefined or cyclic type, an array size out of range, unknown incompatible
// flags) is kInvalidInput naming the byte offset and the message index (0 = the first message
// after the 16-byte header), with `file_name` as the Status file; *log is then left empty.
// More samples than limits.max_samples is kInvalidInput naming the limit. Work is linear in the
// size of the input; memory is the streams plus the definitions (at most 250 000 fields in
// all formats, else kInvalidInput). Thread-compatible.
Status ReadULog(std::string_view bytes, const std::string& file_name, const SensorLogLimits& limits,
                SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_ULOG_H_
