// ArduPilot DataFlash logs (`.bin`, SPEC §9): the sensor streams of a log as a SensorLog
// (formats/sensor_log.h, format "dataflash"). The message framing and FMT definitions are
// formats/dataflash_format.h.
//
// Streams read (topic:instance names them, e.g. "IMU:0"; kind tells accel, gyro and temperature
// of one IMU apart):
//   - IMU per instance `I`: AccX/AccY/AccZ (kAccel, m/s²), GyrX/GyrY/GyrZ (kGyro, rad/s), T
//     (kTemperature, °C). Older logs name instances by message (IMU, IMU2, IMU3, no `I`): they
//     read as IMU:0, IMU:1, IMU:2 with a note.
//   - ACC and GYR (the raw per-sample messages, INS_RAW_LOG_OPT) per instance `I`: kAccel, kGyro.
//   - MAG per instance `I` (older MAG2, MAG3 as above): MagX/MagY/MagZ (kMag), written in
//     milligauss, converted to µT (×0.1).
//   - ISBD, the batch sampler's high-rate batches (INS_LOG_BAT_MASK): per ISBH sensor type and
//     instance, kAccel or kGyro, named "ISBD:instance"; sample k of a batch at the ISBH's
//     SampleUS + k / smp_rate, values the stored integers / mul. Batches are seconds apart (the
//     stream has gaps); post-filter batches appear as instances after the sensors' own, as
//     ArduPilot numbers them. An ISBD whose ISBH is missing or unreadable is not read (warning).
//   Where the log has FMTU (units and multipliers per field) with UNIT and MULT, the unit and
//   multiplier come from them (a field whose unit is not the one above is not read: warning);
//   else the defaults above. device_id: the ArduPilot device id parameter of the instance where
//   the log's PARM messages give it (INS_ACC_ID, INS_ACC2_ID, INS_ACC3_ID for accel and
//   temperature, INS_GYR*_ID for gyro, COMPASS_DEV_ID, COMPASS_DEV_ID2, ... for mag), else -1.
// Time (but ISBD, above): `SampleUS` where the message has it and it is non-zero in every sample of
// the stream, else `TimeUS` (`TimeMS` in the oldest logs); µs or ms to ns exactly; time_source says
// which.
//
// Damage: bytes that do not start a message of a defined type (junk between messages, as real
// logs have) are skipped to the next 0xA3 0x95 as ArduPilot's tools do, counted in a warning. A
// log cut inside a message reads to the last whole message, with a warning naming the byte
// offset. A FMT with an undefined format character, a length that disagrees with its format, or
// column names that do not match it, is kInvalidInput naming the byte offset and message index
// (1-based, over the whole messages read); so is an input with no FMT message at all, a sample
// time out of range, or more samples than SensorLogLimits::max_samples. Work is linear in the
// bytes; memory is the samples read.
#ifndef CALIBD_FORMATS_DATAFLASH_H_
#define CALIBD_FORMATS_DATAFLASH_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Reads the DataFlash log `bytes` (the whole file; `file_name` names it in errors) into *log,
// replacing its contents. On failure *log is left empty. Thread-compatible: no shared state.
Status ReadDataFlash(std::string_view bytes, const std::string& file_name,
                     const SensorLogLimits& limits, SensorLog* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_DATAFLASH_H_
