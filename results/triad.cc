#include "results/triad.h"

#include <utility>

namespace calibd::results {

using nlohmann::json;

json ToJson(const SensorTriad& t) {
  return {{"bias", Nums(t.bias)},
          {"scale", Nums(t.scale)},
          {"misalignment", Rows(t.misalignment)},
          {"matrix", Rows(t.matrix)}};
}

json ToJson(const SensorTriadStd& t) {
  return {{"bias_std", Nums(t.bias_std)},
          {"scale_std", Nums(t.scale_std)},
          {"misalignment_std", Rows(t.misalignment_std)}};
}

void ReadTriad(const JsonReader& r, const char* key, SensorTriad* out) {
  JsonReader t = r.Object(key);
  SensorTriad v;
  t.Read("bias", &v.bias);
  t.Read("scale", &v.scale);
  t.Read("misalignment", &v.misalignment);
  t.Read("matrix", &v.matrix);
  if (t.ok()) *out = v;
}

void ReadTriad(const JsonReader& r, const char* key, SensorTriadStd* out) {
  JsonReader t = r.Object(key);
  SensorTriadStd v;
  t.Read("bias_std", &v.bias_std);
  t.Read("scale_std", &v.scale_std);
  t.Read("misalignment_std", &v.misalignment_std);
  if (t.ok()) *out = v;
}

void ReadImuTriads(const JsonReader& r, ImuTriads* out) {
  ImuTriads v;
  r.Read("name", &v.name);
  ReadTriad(r, "accelerometer", &v.accelerometer);
  ReadTriad(r, "gyroscope", &v.gyroscope);
  if (r.ok()) *out = std::move(v);
}

void ReadImuTriads(const JsonReader& r, ImuTriadsStd* out) {
  ImuTriadsStd v;
  r.Read("name", &v.name);
  ReadTriad(r, "accelerometer", &v.accelerometer);
  ReadTriad(r, "gyroscope", &v.gyroscope);
  if (r.ok()) *out = std::move(v);
}

void WriteImuTriads(const ImuTriads& t, json* out) {
  (*out)["name"] = t.name;
  (*out)["accelerometer"] = ToJson(t.accelerometer);
  (*out)["gyroscope"] = ToJson(t.gyroscope);
}

void WriteImuTriads(const ImuTriadsStd& t, json* out) {
  (*out)["name"] = t.name;
  (*out)["accelerometer"] = ToJson(t.accelerometer);
  (*out)["gyroscope"] = ToJson(t.gyroscope);
}

}  // namespace calibd::results
