#include "formats/csv_dialect.h"

#include <charconv>
#include <map>

#include "base/utf8.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// The longest file column name config `columns` takes (header names are at most a line long;
// this keeps messages and stored configs small).
constexpr size_t kMaxMappedName = 256;

std::string Shown(std::string_view s) {
  std::string out(s.substr(0, 40));
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return s.size() <= 40 ? out : out + "...";
}

Status ParseColumns(const json& columns, CsvDialect* dialect) {
  if (!columns.is_object()) {
    return Status::InvalidInput(
               "'columns' must be an object mapping calibd's column names to the file's "
               "(e.g. {\"t\": \"timestamp\", \"a0_x\": \"accX\"})")
        .WithField("columns");
  }
  std::map<std::string, std::string> by_file_name;  // file name → the key that names it
  for (const auto& [key, value] : columns.items()) {
    const std::string field = "columns." + key;
    if (!IsCalibdColumnName(key)) {
      return Status::InvalidInput("'" + Shown(key) +
                                  "' is not a calibd column name: 'columns' maps t, aK_x, "
                                  "aK_y, aK_z, gK_*, mK_*, temp, tempK, position and phase to "
                                  "the file's names")
          .WithField(field);
    }
    if (!value.is_string() || value.get_ref<const std::string&>().empty()) {
      return Status::InvalidInput("'" + field +
                                  "' must be the file's column name (a non-empty string), not " +
                                  value.dump().substr(0, 40))
          .WithField(field);
    }
    const std::string& name = value.get_ref<const std::string&>();
    bool printable = IsValidUtf8(name) && name.size() <= kMaxMappedName;
    for (char c : name) printable &= static_cast<unsigned char>(c) >= 0x20 && c != 0x7f;
    if (!printable) {
      return Status::InvalidInput(
                 "'" + field + "' must be a printable UTF-8 column name of at most " +
                 std::to_string(kMaxMappedName) + " bytes, not '" + Shown(name) + "'")
          .WithField(field);
    }
    auto [it, inserted] = by_file_name.emplace(name, key);
    if (!inserted) {
      return Status::InvalidInput("'columns." + it->second + "' and '" + field +
                                  "' both name the file's column '" + Shown(name) +
                                  "': one column is one calibd column")
          .WithField(field);
    }
    dialect->columns.emplace_back(key, name);
  }
  return Status::Ok();
}

}  // namespace

json CsvDialect::ToJson() const {
  json mapping = json::object();
  for (const auto& [calibd_name, file_name] : columns) mapping[calibd_name] = file_name;
  return {{"columns", mapping},
          {"delimiter", std::string(1, delimiter)},
          {"decimal", std::string(1, decimal)}};
}

bool HasCsvDialectKeys(const json& config) {
  if (!config.is_object()) return false;
  for (const char* key : kCsvDialectKeys) {
    if (config.contains(key)) return true;
  }
  return false;
}

Status ParseCsvDialect(const json& config, CsvDialect* dialect) {
  *dialect = CsvDialect();
  if (!config.is_object()) return Status::Ok();
  if (auto it = config.find("columns"); it != config.end()) {
    Status s = ParseColumns(*it, dialect);
    if (!s.ok()) return s;
  }
  if (auto it = config.find("delimiter"); it != config.end()) {
    const std::string text = it->is_string() ? it->get<std::string>() : it->dump();
    if (text == "," || text == ";" || text == "\t") {
      dialect->delimiter = text[0];
    } else if (text == "tab") {
      dialect->delimiter = '\t';
    } else {
      return Status::InvalidInput(
                 "'delimiter' must be \",\" (default), \";\" or \"\\t\" (a tab; "
                 "also \"tab\"), not " +
                 it->dump().substr(0, 40))
          .WithField("delimiter");
    }
  }
  if (auto it = config.find("decimal"); it != config.end()) {
    const std::string text = it->is_string() ? it->get<std::string>() : it->dump();
    if (text != "." && text != ",") {
      return Status::InvalidInput("'decimal' must be \".\" (default) or \",\", not " +
                                  it->dump().substr(0, 40))
          .WithField("decimal");
    }
    dialect->decimal = text[0];
  }
  if (dialect->decimal == ',' && dialect->delimiter == ',') {
    return Status::InvalidInput(
               "'decimal' \",\" needs a 'delimiter' other than \",\" (\";\" or \"\\t\"): with "
               "both \",\" a field \"1,5\" would be two numbers")
        .WithField("decimal");
  }
  return Status::Ok();
}

bool IsTemperatureColumn(std::string_view name) {
  if (name.substr(0, 4) != "temp") return false;
  const std::string_view digits = name.substr(4);
  if (digits.empty()) return true;
  if (digits.size() > 1 && digits[0] == '0') return false;
  for (char c : digits) {
    if (c < '0' || c > '9') return false;
  }
  return digits.size() <= 6;
}

bool ParseTriadColumn(std::string_view name, char* kind, int* index, int* axis) {
  if (name.size() < 4 || (name[0] != 'a' && name[0] != 'g' && name[0] != 'm')) return false;
  const size_t underscore = name.find('_');
  if (underscore == std::string_view::npos || underscore < 2 || underscore + 2 != name.size()) {
    return false;
  }
  const std::string_view digits = name.substr(1, underscore - 1);
  if (digits.size() > 1 && digits[0] == '0') return false;  // "a01_x" is not a0/a1
  int value = 0;
  auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  if (ec != std::errc() || ptr != digits.data() + digits.size() || value < 0) return false;
  const char axis_char = name.back();
  if (axis_char < 'x' || axis_char > 'z') return false;
  *kind = name[0];
  *index = value;
  *axis = axis_char - 'x';
  return true;
}

bool IsArrayColumnName(std::string_view name) {
  char kind;
  int index, axis;
  return name == "t" || IsTemperatureColumn(name) || ParseTriadColumn(name, &kind, &index, &axis);
}

bool IsCalibdColumnName(std::string_view name) {
  return IsArrayColumnName(name) || name == "position" || name == "phase";
}

}  // namespace calibd::server
