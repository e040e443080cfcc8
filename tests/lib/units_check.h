// Checks that the numbers a result shows a user name their unit (issue 28 item 3): in a message,
// each number followed by its unit or standing in a clause that names a dimensionless quantity;
// in diagnostics, each non-integer number covered by a unit key (a sibling "unit", "units" or
// "<key>_unit", the result's diagnostics.units map, diagnostics.accel_unit / gyro_unit for the
// accelerometer / gyroscope figures) or by a key naming its unit or ratio (…_ms, chi2…).
#pragma once

#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <string_view>
#include <vector>

namespace calibd::testing {

// The numbers in `text` (with 30 characters of context) that neither carry a unit nor stand in a
// clause naming a dimensionless quantity. Integers are counts or indices and are not checked.
inline std::vector<std::string> NumbersWithoutUnit(const std::string& text) {
  // Units as the messages write them; single letters only when no letter follows.
  static const char* const kUnits[] = {
      "m/s^2", "m/s²", "m/s", "rad^2/s^4", "rad²/s⁴", "(rad/s)^2",     "rad/s", "mrad", "rad",
      "deg/s", "°/s",  "°C",  "°",         "degrees", "reading units", "µm",    "mm",   "ms",
      "min",   "days", "Hz",  "%",         "×",       "times",         "ppm",   "dB"};
  static const char* const kLetterUnits[] = {"s", "m", "h", "x", "um"};
  // Words of a clause whose numbers are dimensionless (ratios, eigenvalues of unitless matrices,
  // unit vectors), up to the clause's start: "(", ";", ":" or ". ".
  static const char* const kDimensionless[] = {
      "ratio",      "χ²",         "chi2",     "chi²", "eigenvalues", "scatter_min",
      "design_min", "multiplier", "fraction", "×",    "direction",   "times the largest"};
  static const std::regex kNumber(R"([-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)");
  // Between two numbers, words that let them share the second's unit: "0.1 and 0.2 m/s^2",
  // "1.02 against 1.00 reading units", "0.05/0.06 rad/s", "gyro_unit 0.0001745 = 0.0001745 rad/s".
  static const char* const kShared[] = {" against ", " and ", " to ", " = ", "/", " ... ", " or "};
  struct Figure {
    size_t at, end;
    std::string number;
    bool decimal, ok;
  };
  std::vector<Figure> figures;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), kNumber);
       it != std::sregex_iterator(); ++it) {
    const std::smatch& m = *it;
    const size_t at = static_cast<size_t>(m.position(0));
    const std::string number = m.str(0);
    // Part of a name (a0_z, g12, T[0]) or of a longer number: not a figure.
    if (at > 0) {
      const char p = text[at - 1];
      if (std::isalnum(static_cast<unsigned char>(p)) || p == '_' || p == '.' || p == '[' ||
          p == '^')
        continue;
    }
    std::string_view after(text);
    after.remove_prefix(at + number.size());
    if (!after.empty() && after.front() == ' ') after.remove_prefix(1);
    bool ok = false;
    for (const char* u : kUnits) ok |= after.substr(0, std::string_view(u).size()) == u;
    for (const char* u : kLetterUnits) {
      const size_t n = std::string_view(u).size();
      if (after.substr(0, n) == u &&
          (after.size() == n || !std::isalpha(static_cast<unsigned char>(after[n]))))
        ok = true;
    }
    // A parenthesis right after the number saying it is relative: "0.25 (relative: ...)".
    for (const char* d : {"(relative", "(ratio", "(fraction"})
      ok |= after.substr(0, std::string_view(d).size()) == d;
    if (!ok) {
      size_t start = 0;
      for (const char* d : {"(", ";", ":", ". "}) {
        const size_t k = text.rfind(d, at);
        if (k != std::string::npos && k + 1 > start) start = k + 1;
      }
      // A parenthesis keeps the word before it: "direction (0.1, 0.9, 0.0)".
      if (start > 0 && text[start - 1] == '(') start = start > 13 ? start - 13 : 0;
      const std::string clause = text.substr(start, at - start);
      for (const char* d : kDimensionless) ok |= clause.find(d) != std::string::npos;
    }
    figures.push_back(
        {at, at + number.size(), number, number.find_first_of(".eE") != std::string::npos, ok});
  }
  for (size_t i = figures.size(); i-- > 1;) {
    Figure& f = figures[i - 1];
    const Figure& next = figures[i];
    const std::string between = text.substr(f.end, next.at - f.end);
    for (const char* w : kShared) f.ok |= between == w && next.ok;
  }
  std::vector<std::string> out;
  for (const Figure& f : figures) {
    // Integers are counts or indices, not checked.
    if (!f.decimal || f.ok) continue;
    const size_t from = f.at > 30 ? f.at - 30 : 0;
    out.push_back(f.number + " in \"..." + text.substr(from, f.end + 30 - from) + "...\"");
  }
  return out;
}

namespace units_internal {

// "a[].b.c, d" -> {"a[].b.c", "a[].b.d"}: the names after a comma share the first one's parent.
inline std::vector<std::string> ExpandUnitKey(const std::string& key) {
  std::vector<std::string> out;
  size_t begin = 0;
  std::string parent;
  while (begin <= key.size()) {
    size_t end = key.find(", ", begin);
    if (end == std::string::npos) end = key.size();
    const std::string name = key.substr(begin, end - begin);
    if (out.empty()) {
      const size_t dot = name.rfind('.');
      parent = dot == std::string::npos ? "" : name.substr(0, dot + 1);
      out.push_back(name);
    } else {
      out.push_back(parent + name);
    }
    begin = end + 2;
  }
  return out;
}

// `pattern` with "*" for any one member name matches `path`.
inline bool PathMatches(const std::string& pattern, const std::string& path) {
  std::string re;
  for (char c : pattern) {
    if (c == '*')
      re += "[^.]+";
    else if (std::string_view(".[]^$+?(){}|\\").find(c) != std::string_view::npos)
      re += std::string("\\") + c;
    else
      re += c;
  }
  return std::regex_match(path, std::regex(re));
}

inline bool NamesItsUnit(const std::string& key) {
  for (const char* s :
       {"_ms", "_seconds", "_rad", "_deg", "chi2", "ratio", "fraction", "multiplier", "_unit"}) {
    if (key.find(s) != std::string::npos) return true;
  }
  return false;
}

struct Walk {
  const nlohmann::json& diag;
  std::vector<std::string> unit_paths;  // from diagnostics.units
  std::vector<std::string>* missing;
  int* checked;

  // `parent`: the object holding `key`; `path`: "a[].b"; `keys`: every key on the way.
  void Visit(const nlohmann::json& x, const nlohmann::json* parent, const std::string& key,
             const std::string& path, bool named) {
    if (x.is_object()) {
      for (const auto& [k, v] : x.items()) {
        if (k == "units" || k == "unit") continue;
        Visit(v, &x, k, path.empty() ? k : path + "." + k, named || NamesItsUnit(k));
      }
    } else if (x.is_array()) {
      for (const auto& v : x) Visit(v, parent, key, path + (v.is_structured() ? "[]" : ""), named);
    } else if (x.is_number_float()) {
      ++*checked;
      if (!Covered(parent, key, path, named)) {
        for (const std::string& m : *missing)
          if (m == path) return;
        missing->push_back(path);
      }
    }
  }

  bool Covered(const nlohmann::json* parent, const std::string& key, const std::string& path,
               bool named) const {
    if (named) return true;
    if (parent && parent->is_object()) {
      if (parent->contains("unit") && (*parent)["unit"].is_string()) return true;
      if (parent->contains(key + "_unit")) return true;
      if (parent->contains("units") && (*parent)["units"].is_string()) return true;
      if (parent->contains("units") && (*parent)["units"].is_object() &&
          (*parent)["units"].contains(key))
        return true;
    }
    for (const std::string& p : unit_paths)
      if (PathMatches(p, path)) return true;
    // Accelerometer and gyroscope figures, in the units diagnostics.accel_unit / gyro_unit name.
    if (path.find("accel") != std::string::npos && diag.contains("accel_unit")) return true;
    if (path.find("gyro") != std::string::npos && diag.contains("gyro_unit")) return true;
    return false;
  }
};

}  // namespace units_internal

// The paths ("imus[].statics[].accel_mean") of the non-integer numbers in `diagnostics` whose
// unit nothing names; *checked counts the numbers looked at.
inline std::vector<std::string> DiagnosticsWithoutUnit(const nlohmann::json& diagnostics,
                                                       int* checked) {
  std::vector<std::string> missing;
  units_internal::Walk walk{diagnostics, {}, &missing, checked};
  if (diagnostics.contains("units") && diagnostics["units"].is_object()) {
    for (const auto& [k, v] : diagnostics["units"].items()) {
      if (!v.is_string() || v.get<std::string>().empty()) continue;
      for (const std::string& p : units_internal::ExpandUnitKey(k)) walk.unit_paths.push_back(p);
    }
  }
  walk.Visit(diagnostics, nullptr, "", "", false);
  return missing;
}

}  // namespace calibd::testing
