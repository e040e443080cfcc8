// JsonReader: reads a JSON document (a stored result, a result a user passes to a chain) into
// typed values, and names the path of the first problem it meets
// ("pca result: parameters.sensors[2].scale: expected a number, found a string").
//
// Reading never throws and never stops half-way with garbage: every Read either fills its output
// or leaves it untouched and records the problem; the caller checks status() once at the end.
// Only the first problem is kept (the one a person fixes first).
//
// Conventions of the result documents (SPEC §4, written by results::Num and friends): a number
// that is undefined (NaN, an uncertainty the data cannot give) is written as null and read back
// as NaN, so a double round-trips; a value that may be absent altogether is a std::optional.
// Matrices are arrays of rows.
//
// Thread-compatible; a reader refers to the document, which must outlive it.
#ifndef CALIBD_RESULTS_JSON_READER_H_
#define CALIBD_RESULTS_JSON_READER_H_

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace calibd::results {

class JsonReader {
 public:
  // A reader of `doc`; `what` names the document in messages ("pca result").
  JsonReader(const nlohmann::json& doc, std::string what);

  // kOk, or kInvalidInput naming the document and the path of the first problem (also as
  // Status::field(), e.g. "parameters.sensors[2].scale").
  const Status& status() const { return state_->first; }
  bool ok() const { return state_->first.ok(); }

  // The node this reader reads (null when it is absent).
  const nlohmann::json& node() const;
  // Its path ("" for the root).
  const std::string& path() const { return path_; }

  // Whether member `key` is present and not null.
  bool Has(std::string_view key) const;
  // A reader of member `key`, which must be an object (else a problem, and the reader reads an
  // absent node: every Read through it then fails quietly, the first problem staying the one kept).
  JsonReader Object(std::string_view key) const;
  // The same for an optional member: nullopt when absent or null.
  std::optional<JsonReader> OptionalObject(std::string_view key) const;

  // Required members: present, of the type. A double accepts null (read as NaN).
  void Read(std::string_view key, double* out) const;
  void Read(std::string_view key, int64_t* out) const;  // an integral number
  void Read(std::string_view key, int* out) const;      // an integral number within int
  void Read(std::string_view key, bool* out) const;
  void Read(std::string_view key, std::string* out) const;
  // An array of numbers (null entries read as NaN).
  void Read(std::string_view key, std::vector<double>* out) const;
  void Read(std::string_view key, std::vector<std::string>* out) const;
  void Read(std::string_view key, std::vector<int64_t>* out) const;
  // An array of arrays of numbers (a table, rows of any length).
  void Read(std::string_view key, std::vector<std::vector<double>>* out) const;
  // Exactly 3 numbers / 3 rows of 3 numbers (null entries read as NaN).
  void Read(std::string_view key, Eigen::Vector3d* out) const;
  void Read(std::string_view key, Eigen::Matrix3d* out) const;

  // Optional members: absent or null gives nullopt; present, of the type, the value.
  template <class T>
  void Read(std::string_view key, std::optional<T>* out) const {
    if (!Has(key)) {
      out->reset();
      return;
    }
    T value{};
    const bool was_ok = ok();
    Read(key, &value);
    if (was_ok && ok()) *out = std::move(value);
  }

  // Members a result has but SPEC §4/§7 does not require (our extensions, added over time):
  // read like Read when present (null included), and when absent *out keeps the value it has
  // (the struct's default), so a result stored by an earlier calibd, before the member existed,
  // still reads. Writers always write them.
  template <class T>
  void ReadExtension(std::string_view key, T* out) const {
    if (Present(key)) Read(key, out);
  }
  template <class T, class F>
  void ReadArrayExtension(std::string_view key, std::vector<T>* out, F read_one) const {
    if (Present(key)) ReadArray(key, out, read_one);
  }
  // Whether member `key` exists (null included).
  bool Present(std::string_view key) const;

  // An array of objects: `read_one(element_reader, &element)` for each, in order. Requires the
  // array (an empty one is fine).
  template <class T, class F>
  void ReadArray(std::string_view key, std::vector<T>* out, F read_one) const {
    const nlohmann::json* array = Child(key, "an array", &nlohmann::json::is_array);
    if (array == nullptr) return;
    std::vector<T> values(array->size());
    for (size_t i = 0; i < array->size(); ++i) {
      JsonReader element = Element(key, i);
      if (!(*array)[i].is_object()) {
        element.Fail("expected an object, found " + TypeName((*array)[i]));
        return;
      }
      read_one(element, &values[i]);
      if (!ok()) return;
    }
    *out = std::move(values);
  }

  // The member as it is (any JSON, null when absent): only for parts of a document whose shape is
  // open by design (e.g. the config echoed into a result). Not a way around typing a field.
  void ReadRaw(std::string_view key, nlohmann::json* out) const;

  // Records a problem at this reader's path (or at path.key when `key` is not empty): for checks
  // the types cannot express ("unknown frame \"x\"", "3 sensors but 2 uncertainties").
  void Fail(const std::string& message, std::string_view key = {}) const;

  // "a number", "a string", ... for messages.
  static std::string TypeName(const nlohmann::json& j);

 private:
  struct State {
    Status first;
    std::string what;
  };
  JsonReader(const nlohmann::json* node, std::string path, std::shared_ptr<State> state);
  std::string PathOf(std::string_view key) const;
  JsonReader Element(std::string_view key, size_t i) const;
  // The member if present and `is(member)`; else records "missing" or "expected `type`" and
  // returns null (also null, quietly, once a problem is recorded or when this node is absent).
  const nlohmann::json* Child(std::string_view key, const char* type,
                              bool (nlohmann::json::*is)() const noexcept) const;

  const nlohmann::json* node_;  // null: absent (after a problem)
  std::string path_;
  std::shared_ptr<State> state_;
};

// ---- Writing (the other half of the conventions above) ----

// x, or null when not finite.
nlohmann::json Num(double x);
// x, or null when absent or not finite.
nlohmann::json Num(const std::optional<double>& x);
// Each entry as Num.
nlohmann::json Nums(const std::vector<double>& v);
nlohmann::json Nums(const Eigen::Vector3d& v);
// Rows of Num.
nlohmann::json Rows(const Eigen::Matrix3d& m);
nlohmann::json Rows(const std::vector<std::vector<double>>& rows);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_JSON_READER_H_
