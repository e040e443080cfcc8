// Representations of a stored calibration for production tooling (GET .../calibration?format=):
// the result JSON as stored, CSV (one row per sensor / triad), and a C99/C++ header. Each method
// writes its own (Method::Export, server/<name>_exports.cc); the functions here find the
// result's method in the registry and ask it.
#ifndef CALIBD_SERVER_EXPORTS_H_
#define CALIBD_SERVER_EXPORTS_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"

namespace calibd::server {

// A representation of a method's results for production tooling besides the result JSON
// (GET /api/v1/devices/{serial}/calibration?format=FORMAT).
struct ExportFormat {
  std::string format;        // the query's value: "csv", "h", "yaml"
  std::string label;         // link text on the pages: "CSV", "C header", "Kalibr imu.yaml"
  std::string content_type;  // of the answer: "text/csv"
  std::string file_name;     // Content-Disposition file name; "": calibration-JOB.FORMAT
};

// CSV (one row per sensor / triad / channel) and the C header: every method has both.
ExportFormat CsvFormat();
ExportFormat CHeaderFormat();
// kInvalidInput naming `format`: "<method> results have no format=FORMAT".
Status NoSuchExport(const std::string& format, const char* method);

// Who and when, for the header comment of the exports.
struct ExportContext {
  int64_t job_id = 0;
  std::string device;
  std::string method;
  std::string finished_at;  // ISO-8601
  // The result's standing (ServeState name): "" or "accepted" for what is served as the device's
  // calibration; "rejected" (by the gate) or "revoked" (by a person) for a result fetched with
  // ?job=, which the file then marks as not for use (C header: ACCEPTED 0 and a comment; CSV and
  // yaml: a first comment line).
  std::string state = "";
  // The job's config (JSON object; null when not known). Exports that convert readings to SI
  // read the nominal bias of offset-binary counts from it (nominal_accel_bias,
  // nominal_gyro_bias; absent = 0).
  nlohmann::json config = nullptr;
};

// Whether `context` is a result that is served as a calibration (state "" or "accepted").
inline bool IsAcceptedExport(const ExportContext& context) {
  return context.state.empty() || context.state == "accepted";
}

// For a result that is not served (IsAcceptedExport false): puts a comment line saying so at the
// top of a CSV or yaml export `text` (after a leading "%YAML" directive, which must stay first).
// Other formats and accepted results are left as they are (the C header marks itself, JSON has
// "state").
void MarkNotAccepted(const std::string& format, const ExportContext& context, std::string* text);

// pca: name,scale,scale_std,axis_*,axis_std_rad,bias,bias_std,sensitivity_*;
// array: name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z. Full double precision.
// kInternal if the result lacks the SPEC keys (a stored result always has them) or names no
// known method.
Status ResultToCsv(const nlohmann::json& result, std::string* out);
// Kalibr's imu.yaml (accelerometer_/gyroscope_noise_density and _random_walk, the largest over
// the axes, update_rate) of a noise result; for an imu result, OpenVINS's kalibr_imu_chain.yaml
// (methods/imu/openvins_yaml.h). kInvalidInput for other methods; kNotDeterminable when a figure is
// null (the log could not show it).
Status ResultToKalibrYaml(const nlohmann::json& result, const ExportContext& context,
                          std::string* out);

// A self-contained header, valid C99 and C++ (no namespace, no constexpr): `static const` arrays,
// macros and one `static inline` function per method that applies the calibration to one raw
// reading (pca: the field by the least-squares inverse; imu, and array results with per-IMU
// intrinsics: both triads); array positions and noise figures as data. Every identifier starts
// with CALIBD_<SERIAL>_<METHOD>_ (functions in lower case; serial and method with every byte other
// than a letter or digit as '_'), and the include guard names the job, so headers of several
// devices and methods go into one program; two jobs of one device and method collide loudly.
// The comment states the model equation, device, job and time. An undefined σ is omitted (with a
// comment), never written as 0; an undefined parameter gives kNotDeterminable. Strings from users
// are sanitised for comments and escaped in string literals.
Status ResultToHeader(const nlohmann::json& result, const ExportContext& context, std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_EXPORTS_H_
