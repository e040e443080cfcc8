#include "results/json_reader.h"

#include <cmath>
#include <limits>
#include <utility>

namespace calibd::results {

using nlohmann::json;

namespace {

const json& AbsentNode() {
  static const json* absent = new json();
  return *absent;
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A number or null (NaN).
bool NumberOrNull(const json& j, double* out) {
  if (j.is_null()) {
    *out = kNaN;
    return true;
  }
  if (!j.is_number()) return false;
  *out = j.get<double>();
  return true;
}

}  // namespace

JsonReader::JsonReader(const json& doc, std::string what)
    : node_(&doc), state_(std::make_shared<State>()) {
  state_->what = std::move(what);
}

JsonReader::JsonReader(const json* node, std::string path, std::shared_ptr<State> state)
    : node_(node), path_(std::move(path)), state_(std::move(state)) {}

const json& JsonReader::node() const { return node_ != nullptr ? *node_ : AbsentNode(); }

std::string JsonReader::PathOf(std::string_view key) const {
  if (key.empty()) return path_;
  return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
}

std::string JsonReader::TypeName(const json& j) {
  switch (j.type()) {
    case json::value_t::null:
      return "null";
    case json::value_t::object:
      return "an object";
    case json::value_t::array:
      return "an array";
    case json::value_t::string:
      return "a string";
    case json::value_t::boolean:
      return "a boolean";
    case json::value_t::number_integer:
    case json::value_t::number_unsigned:
    case json::value_t::number_float:
      return "a number";
    default:
      return "an unknown value";
  }
}

void JsonReader::Fail(const std::string& message, std::string_view key) const {
  if (!state_->first.ok()) return;
  const std::string path = PathOf(key);
  state_->first = Status::InvalidInput(state_->what + ": " +
                                       (path.empty() ? std::string() : path + ": ") + message)
                      .WithField(path);
}

bool JsonReader::Has(std::string_view key) const {
  if (node_ == nullptr || !node_->is_object()) return false;
  auto it = node_->find(key);
  return it != node_->end() && !it->is_null();
}

bool JsonReader::Present(std::string_view key) const {
  return node_ != nullptr && node_->is_object() && node_->find(key) != node_->end();
}

const json* JsonReader::Child(std::string_view key, const char* type,
                              bool (json::*is)() const noexcept) const {
  if (!ok() || node_ == nullptr) return nullptr;
  if (!node_->is_object()) {
    Fail("expected an object, found " + TypeName(*node_));
    return nullptr;
  }
  auto it = node_->find(key);
  if (it == node_->end()) {
    Fail("missing", key);
    return nullptr;
  }
  if (!((*it).*is)()) {
    Fail(std::string("expected ") + type + ", found " + TypeName(*it), key);
    return nullptr;
  }
  return &*it;
}

JsonReader JsonReader::Object(std::string_view key) const {
  const json* child = Child(key, "an object", &json::is_object);
  return JsonReader(child, PathOf(key), state_);
}

std::optional<JsonReader> JsonReader::OptionalObject(std::string_view key) const {
  if (!Has(key)) return std::nullopt;
  return Object(key);
}

JsonReader JsonReader::Element(std::string_view key, size_t i) const {
  const json* array = nullptr;
  if (node_ != nullptr && node_->is_object()) {
    auto it = node_->find(key);
    if (it != node_->end()) array = &*it;
  }
  const json* element = array != nullptr && i < array->size() ? &(*array)[i] : nullptr;
  return JsonReader(element, PathOf(key) + "[" + std::to_string(i) + "]", state_);
}

void JsonReader::Read(std::string_view key, double* out) const {
  const json* j = Child(key, "a number", &json::is_primitive);
  if (j == nullptr) return;
  double x = 0;
  if (!NumberOrNull(*j, &x)) {
    Fail("expected a number, found " + TypeName(*j), key);
    return;
  }
  *out = x;
}

namespace {

// A JSON number that is an int64 exactly: an integer in range, or a whole float within 2^53 (a
// larger float may not be the integer it was written as). "" on success, else why not.
std::string Integer(const json& j, int64_t* out) {
  if (j.is_number_float()) {
    const double x = j.get<double>();
    if (!(std::floor(x) == x && std::fabs(x) < 9.007199254740992e15)) {
      return "expected an integer, found " + j.dump();
    }
    *out = static_cast<int64_t>(x);
    return "";
  }
  if (!j.is_number()) return "expected an integer, found " + JsonReader::TypeName(j);
  if (j.is_number_unsigned() &&
      j.get<uint64_t>() > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
    return "integer out of range: " + j.dump();
  }
  *out = j.get<int64_t>();
  return "";
}

}  // namespace

void JsonReader::Read(std::string_view key, int64_t* out) const {
  const json* j = Child(key, "an integer", &json::is_number);
  if (j == nullptr) return;
  int64_t v = 0;
  if (const std::string why = Integer(*j, &v); !why.empty()) {
    Fail(why, key);
    return;
  }
  *out = v;
}

void JsonReader::Read(std::string_view key, int* out) const {
  int64_t v = 0;
  const bool was_ok = ok();
  Read(key, &v);
  if (!was_ok || !ok()) return;
  if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max()) {
    Fail("integer out of range: " + std::to_string(v), key);
    return;
  }
  *out = static_cast<int>(v);
}

void JsonReader::Read(std::string_view key, bool* out) const {
  const json* j = Child(key, "a boolean", &json::is_boolean);
  if (j != nullptr) *out = j->get<bool>();
}

void JsonReader::Read(std::string_view key, std::string* out) const {
  const json* j = Child(key, "a string", &json::is_string);
  if (j != nullptr) *out = j->get<std::string>();
}

void JsonReader::Read(std::string_view key, std::vector<double>* out) const {
  const json* j = Child(key, "an array of numbers", &json::is_array);
  if (j == nullptr) return;
  std::vector<double> v(j->size());
  for (size_t i = 0; i < j->size(); ++i) {
    if (!NumberOrNull((*j)[i], &v[i])) {
      Fail("expected a number, found " + TypeName((*j)[i]),
           std::string(key) + "[" + std::to_string(i) + "]");
      return;
    }
  }
  *out = std::move(v);
}

void JsonReader::Read(std::string_view key, std::vector<std::string>* out) const {
  const json* j = Child(key, "an array of strings", &json::is_array);
  if (j == nullptr) return;
  std::vector<std::string> v(j->size());
  for (size_t i = 0; i < j->size(); ++i) {
    if (!(*j)[i].is_string()) {
      Fail("expected a string, found " + TypeName((*j)[i]),
           std::string(key) + "[" + std::to_string(i) + "]");
      return;
    }
    v[i] = (*j)[i].get<std::string>();
  }
  *out = std::move(v);
}

void JsonReader::Read(std::string_view key, std::vector<int64_t>* out) const {
  const json* j = Child(key, "an array of integers", &json::is_array);
  if (j == nullptr) return;
  std::vector<int64_t> v(j->size());
  for (size_t i = 0; i < j->size(); ++i) {
    if (const std::string why = Integer((*j)[i], &v[i]); !why.empty()) {
      Fail(why, std::string(key) + "[" + std::to_string(i) + "]");
      return;
    }
  }
  *out = std::move(v);
}

void JsonReader::Read(std::string_view key, std::vector<std::vector<double>>* out) const {
  const json* j = Child(key, "an array of rows", &json::is_array);
  if (j == nullptr) return;
  std::vector<std::vector<double>> rows(j->size());
  for (size_t r = 0; r < j->size(); ++r) {
    const std::string row_key = std::string(key) + "[" + std::to_string(r) + "]";
    const json& row = (*j)[r];
    if (!row.is_array()) {
      Fail("expected an array of numbers, found " + TypeName(row), row_key);
      return;
    }
    rows[r].resize(row.size());
    for (size_t c = 0; c < row.size(); ++c) {
      if (!NumberOrNull(row[c], &rows[r][c])) {
        Fail("expected a number, found " + TypeName(row[c]),
             row_key + "[" + std::to_string(c) + "]");
        return;
      }
    }
  }
  *out = std::move(rows);
}

void JsonReader::Read(std::string_view key, Eigen::Vector3d* out) const {
  std::vector<double> v;
  const bool was_ok = ok();
  Read(key, &v);
  if (!was_ok || !ok()) return;
  if (v.size() != 3) {
    Fail("expected 3 numbers, found " + std::to_string(v.size()), key);
    return;
  }
  *out = Eigen::Vector3d(v[0], v[1], v[2]);
}

void JsonReader::Read(std::string_view key, Eigen::Matrix3d* out) const {
  std::vector<std::vector<double>> rows;
  const bool was_ok = ok();
  Read(key, &rows);
  if (!was_ok || !ok()) return;
  if (rows.size() != 3 || rows[0].size() != 3 || rows[1].size() != 3 || rows[2].size() != 3) {
    Fail("expected 3 rows of 3 numbers", key);
    return;
  }
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = rows[r][c];
  }
  *out = m;
}

void JsonReader::ReadRaw(std::string_view key, json* out) const {
  if (!ok() || node_ == nullptr || !node_->is_object()) return;
  auto it = node_->find(key);
  *out = it != node_->end() ? *it : json();
}

// ---- writing ----

json Num(double x) { return std::isfinite(x) ? json(x) : json(); }

json Num(const std::optional<double>& x) { return x ? Num(*x) : json(); }

json Nums(const std::vector<double>& v) {
  json out = json::array();
  for (double x : v) out.push_back(Num(x));
  return out;
}

json Nums(const Eigen::Vector3d& v) { return json::array({Num(v(0)), Num(v(1)), Num(v(2))}); }

json Rows(const Eigen::Matrix3d& m) {
  json out = json::array();
  for (int r = 0; r < 3; ++r) out.push_back(Nums(Eigen::Vector3d(m.row(r).transpose())));
  return out;
}

json Rows(const std::vector<std::vector<double>>& rows) {
  json out = json::array();
  for (const auto& row : rows) out.push_back(Nums(row));
  return out;
}

}  // namespace calibd::results
