// From a sensor log's streams to the recording the methods read (SPEC §9 "Choosing streams",
// "Time"): config `streams` chooses which accelerometer, gyroscope and temperature streams form
// IMU K (by default every IMU of the log), and AssembleLog builds an ArrayRecording from them.
//
// Time, the rules:
//   - An IMU's time base is its gyroscope's sample times (its accelerometer's when it has no
//     gyroscope). Samples whose time does not increase are dropped and counted.
//   - An accelerometer with the gyroscope's very time stamps pairs sample by sample. One on other
//     instants (separate topics at their own rates) is interpolated linearly onto the gyroscope's
//     times, over their common span only, and the IMU says so (`resampled`): interpolation
//     averages neighbouring samples, so its white noise at short averaging times reads lower
//     than it is (up to 1/√2 halfway between samples).
//   - Temperature, slow, is interpolated onto the base (held at its first and last value
//     outside its span), stated per IMU; so are the magnetometers (`mags`, SPEC §8), unless
//     mag_time_base makes the first magnetometer's times the base: then every IMU stream is
//     interpolated onto them instead.
//   - The recording has one time column: IMUs after the first whose time base is not the first's
//     are left out by default, with a warning naming them and the `streams` that calibrates them;
//     asked for explicitly, that is an error (one job per IMU for now).
//   - t is in seconds counted from the first sample's whole second when that is at least
//     kTimeOriginSeconds (epoch stamps, ROS), as for CSV (RecordingSummary::time_origin).
#ifndef CALIBD_FORMATS_LOG_ASSEMBLY_H_
#define CALIBD_FORMATS_LOG_ASSEMBLY_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "formats/recording.h"
#include "formats/sensor_log.h"

namespace calibd::server {

// Config `streams` (SPEC §9): {"imus": [{"accel": NAME, "gyro": NAME, "temp": NAME}], "mags":
// [NAME]}, NAME a SensorStream::Name() ("sensor_accel:0", "IMU:1", "/imu/data"). Within an IMU
// `accel` or `gyro` may be left out (not both); `temp` is optional.
struct LogStreamSelection {
  struct Imu {
    std::string accel, gyro, temp;  // "" = none
  };
  std::vector<Imu> imus;          // empty: every IMU of the log, in order
  std::vector<std::string> mags;  // empty: every magnetometer of the log
  bool given = false;             // the config had `streams`
  // The first magnetometer's times are the time base and the IMUs' streams are interpolated onto
  // them (the mag method: its samples stay independent, not repeated 10× onto a 1 kHz IMU's
  // times). Set by the method (RecordingParser::SetLogTimeBaseMag), not by the config.
  bool mag_time_base = false;
};

// Reads config `streams` (absent: the defaults). kInvalidInput naming the key path
// ("streams.imus[1].gyro") for a value of the wrong shape.
Status ParseLogStreams(const nlohmann::json& config, LogStreamSelection* selection);

struct AssembledLog {
  // aK/gK per IMU K, tempK where the IMU has a temperature stream, mK per magnetometer (µT).
  ArrayRecording recording;
  int64_t time_origin = 0;  // whole seconds subtracted from every t (0: none)
  // What was read, for the recording's JSON and page (SPEC §9 "What was read"):
  // {"format", "time_base", "streams": [...], "imus": [{"index", "accel", "gyro", "temp",
  //   "samples", "dropped", "resampled", "temperature"}], "warnings": [...]}.
  nlohmann::json description;
};

// Builds the recording from the chosen streams. kInvalidInput, with field "streams", for a
// choice the log cannot satisfy (an unknown NAME, a stream of the wrong kind, IMUs on different
// time bases asked for together, no IMU at all); the message lists the log's streams.
Status AssembleLog(const SensorLog& log, const LogStreamSelection& selection,
                   const std::string& file_name, AssembledLog* out);

// One stream as SPEC §9 lists it: {"name", "instance", "device_id", "kind", "samples", "rate",
// "start", "end", "gaps", "unit", "time_source", "note"} (rate in Hz from the median step;
// start/end in s on the log's clock; gaps: steps over 1.5× the median).
nlohmann::json DescribeStream(const SensorStream& stream);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_LOG_ASSEMBLY_H_
