// ULog message formats ('F' messages) and the byte layout of a subscribed one (formats/ulog.h).
// Internal to the ULog reader.
#ifndef CALIBD_FORMATS_ULOG_DEFINITIONS_H_
#define CALIBD_FORMATS_ULOG_DEFINITIONS_H_

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"

namespace calibd::server::ulog {

// The format's basic types (PX4 dev guide, "Data types"); kNested is another format by name.
enum class BasicType {
  kInt8,
  kUInt8,
  kInt16,
  kUInt16,
  kInt32,
  kUInt32,
  kInt64,
  kUInt64,
  kFloat,
  kDouble,
  kBool,
  kChar,
  kNested
};
int BasicTypeSize(BasicType type);  // bytes; 0 for kNested

// One field of a format: "float[3] gyro_rad" is type "float", array 3, name "gyro_rad".
struct FormatField {
  std::string name;
  std::string type_name;  // as written ("float", "vehicle_status_s")
  BasicType type = BasicType::kNested;
  int64_t array = 0;  // 0 for a scalar, else the element count (1..kMaxArray)
};

// A top-level field located in a subscribed message's payload (after the 2-byte msg_id).
struct FieldSlot {
  BasicType type = BasicType::kNested;
  int64_t offset = 0;  // bytes from the start of the data
  int64_t array = 0;   // as FormatField::array
};

// The byte layout of one subscribed format.
struct Layout {
  int64_t size = 0;  // the whole format, trailing `_padding` fields included
  // Without the trailing `_padding` fields, which writers may leave out of 'D' messages: a 'D'
  // payload holds between min_size and size bytes of data.
  int64_t min_size = 0;
  std::map<std::string, FieldSlot, std::less<>> fields;  // top-level fields by name
  // The top-level field `name` with a basic (not nested) type, or nullptr.
  const FieldSlot* Find(std::string_view name) const;
};

inline constexpr int64_t kMaxArray = 65535;  // larger arrays cannot fit in a message

// The formats seen so far, by name. Not thread-safe.
class Definitions {
 public:
  // Parses an 'F' payload "name:type field;type field;..." and stores it. A second definition
  // of a name is ignored when it is the same text, else kInvalidInput (a layout already used
  // could not change). kInvalidInput (without location) for a malformed text, or when the
  // formats define more than 250 000 fields in all (memory bound).
  Status AddFormat(std::string_view text);
  // The layout of format `name`, nested formats resolved; computed once per name, the pointer
  // valid for the Definitions' life. kInvalidInput naming the type for an undefined type, a cycle
  // of nested types, nesting deeper than 32 or a size beyond any message. Work: each format's
  // size and each layout is computed once.
  Status GetLayout(const std::string& name, const Layout** layout);

 private:
  struct Format {
    std::string text;  // as written, to compare a redefinition
    std::vector<FormatField> fields;
  };
  Status SizeOf(const std::string& name, int depth, int64_t* size);

  std::map<std::string, Format, std::less<>> formats_;
  // Memo of SizeOf (-1 while in progress: met again, a cycle) and of GetLayout. Entries stay
  // valid: formats are never redefined.
  std::map<std::string, int64_t, std::less<>> sizes_;
  std::map<std::string, Layout, std::less<>> layouts_;
  int64_t total_fields_ = 0;  // over all 'F' messages, at most kMaxFields
};

}  // namespace calibd::server::ulog

#endif  // CALIBD_FORMATS_ULOG_DEFINITIONS_H_
