// ULog message formats and layouts (formats/ulog_definitions.h).
#include "formats/ulog_definitions.h"

#include <utility>

namespace calibd::server::ulog {

namespace {

// The largest data a 'D' message can hold: a uint16 payload size less the 2-byte msg_id.
constexpr int64_t kMaxDataBytes = 65535 - 2;
// More fields over all formats are refused: bounds the memory of the definitions (~100 B per
// field with its layout) whatever the log's size.
constexpr int64_t kMaxFields = 250'000;
// Nesting deeper than this is refused (PX4's messages nest two or three levels).
constexpr int kMaxNesting = 32;

struct NamedType {
  const char* name;
  BasicType type;
};
constexpr NamedType kBasicTypes[] = {
    {"int8_t", BasicType::kInt8},   {"uint8_t", BasicType::kUInt8},
    {"int16_t", BasicType::kInt16}, {"uint16_t", BasicType::kUInt16},
    {"int32_t", BasicType::kInt32}, {"uint32_t", BasicType::kUInt32},
    {"int64_t", BasicType::kInt64}, {"uint64_t", BasicType::kUInt64},
    {"float", BasicType::kFloat},   {"double", BasicType::kDouble},
    {"bool", BasicType::kBool},     {"char", BasicType::kChar},
};

BasicType TypeByName(std::string_view name) {
  for (const NamedType& t : kBasicTypes)
    if (name == t.name) return t.type;
  return BasicType::kNested;
}

std::string Quoted(std::string_view text) { return "'" + std::string(text.substr(0, 64)) + "'"; }

// "type[N] name" or "type name" → *field.
Status ParseField(std::string_view text, FormatField* field) {
  const size_t space = text.find(' ');
  if (space == std::string_view::npos || space == 0 || space + 1 == text.size())
    return Status::InvalidInput("field " + Quoted(text) + " is not 'type name'");
  std::string_view type = text.substr(0, space);
  field->name = std::string(text.substr(space + 1));
  field->array = 0;
  const size_t open = type.find('[');
  if (open != std::string_view::npos) {
    if (type.back() != ']' || open == 0 || open + 2 >= type.size())
      return Status::InvalidInput("field " + Quoted(text) + " has a malformed array size");
    int64_t count = 0;
    for (char c : type.substr(open + 1, type.size() - open - 2)) {
      if (c < '0' || c > '9' || count > kMaxArray)
        return Status::InvalidInput("field " + Quoted(text) + " has a malformed array size");
      count = count * 10 + (c - '0');
    }
    if (count < 1 || count > kMaxArray)
      return Status::InvalidInput("field " + Quoted(text) + " has array size " +
                                  std::to_string(count) + " (1 to 65535)");
    field->array = count;
    type = type.substr(0, open);
  }
  field->type_name = std::string(type);
  field->type = TypeByName(type);
  return Status::Ok();
}

}  // namespace

int BasicTypeSize(BasicType type) {
  switch (type) {
    case BasicType::kInt8:
    case BasicType::kUInt8:
    case BasicType::kBool:
    case BasicType::kChar:
      return 1;
    case BasicType::kInt16:
    case BasicType::kUInt16:
      return 2;
    case BasicType::kInt32:
    case BasicType::kUInt32:
    case BasicType::kFloat:
      return 4;
    case BasicType::kInt64:
    case BasicType::kUInt64:
    case BasicType::kDouble:
      return 8;
    case BasicType::kNested:
      return 0;
  }
  return 0;
}

const FieldSlot* Layout::Find(std::string_view name) const {
  auto it = fields.find(name);
  if (it == fields.end() || it->second.type == BasicType::kNested) return nullptr;
  return &it->second;
}

Status Definitions::AddFormat(std::string_view text) {
  // Writers may end the text with NULs; a string stops at the first.
  text = text.substr(0, text.find('\0'));
  const size_t colon = text.find(':');
  if (colon == std::string_view::npos || colon == 0)
    return Status::InvalidInput("format " + Quoted(text) + " is not 'name:type field;...'");
  std::vector<FormatField> fields;
  std::string_view rest = text.substr(colon + 1);
  while (!rest.empty()) {
    const size_t semicolon = rest.find(';');
    const std::string_view item = rest.substr(0, semicolon);
    rest = semicolon == std::string_view::npos ? std::string_view() : rest.substr(semicolon + 1);
    if (item.empty()) continue;
    FormatField field;
    Status status = ParseField(item, &field);
    if (!status.ok())
      return Status::InvalidInput("format " + Quoted(text.substr(0, colon)) + ": " +
                                  status.message());
    fields.push_back(std::move(field));
  }
  total_fields_ += static_cast<int64_t>(fields.size());
  if (total_fields_ > kMaxFields)
    return Status::InvalidInput("the formats define more than " + std::to_string(kMaxFields) +
                                " fields (PX4 logs define a few thousand)");
  const std::string name(text.substr(0, colon));
  auto [it, added] = formats_.try_emplace(name, Format{std::string(text), std::move(fields)});
  if (!added && it->second.text != text)
    return Status::InvalidInput("format " + Quoted(name) + " is defined twice, differently");
  return Status::Ok();
}

Status Definitions::SizeOf(const std::string& name, int depth, int64_t* size) {
  auto memo = sizes_.find(name);
  if (memo != sizes_.end()) {
    if (memo->second < 0)
      return Status::InvalidInput("type " + Quoted(name) + " contains itself (a cycle of types)");
    *size = memo->second;
    return Status::Ok();
  }
  if (depth > kMaxNesting)
    return Status::InvalidInput("type " + Quoted(name) + " is nested more than " +
                                std::to_string(kMaxNesting) + " levels deep");
  auto format = formats_.find(name);
  if (format == formats_.end())
    return Status::InvalidInput("type " + Quoted(name) + " is not defined (no 'F' message)");
  sizes_[name] = -1;
  int64_t total = 0;
  for (const FormatField& field : format->second.fields) {
    int64_t element = BasicTypeSize(field.type);
    if (field.type == BasicType::kNested) {
      Status status = SizeOf(field.type_name, depth + 1, &element);
      if (!status.ok()) return status;
    }
    total += element * (field.array == 0 ? 1 : field.array);
    if (total > kMaxDataBytes)
      return Status::InvalidInput("type " + Quoted(name) + " is larger than a message can hold (" +
                                  std::to_string(kMaxDataBytes) + " bytes)");
  }
  sizes_[name] = total;
  *size = total;
  return Status::Ok();
}

Status Definitions::GetLayout(const std::string& name, const Layout** layout) {
  auto cached = layouts_.find(name);
  if (cached != layouts_.end()) {
    *layout = &cached->second;
    return Status::Ok();
  }
  int64_t size = 0;
  Status status = SizeOf(name, 0, &size);
  if (!status.ok()) return status;
  Layout made;
  int64_t offset = 0;
  int64_t padding_from = -1;  // offset where the trailing run of _padding fields starts
  for (const FormatField& field : formats_.find(name)->second.fields) {
    int64_t element = BasicTypeSize(field.type);
    if (field.type == BasicType::kNested) element = sizes_.find(field.type_name)->second;
    const bool padding = field.name.rfind("_padding", 0) == 0;
    if (!padding) made.fields[field.name] = FieldSlot{field.type, offset, field.array};
    if (padding && padding_from < 0) padding_from = offset;
    if (!padding) padding_from = -1;
    offset += element * (field.array == 0 ? 1 : field.array);
  }
  made.size = size;
  made.min_size = padding_from < 0 ? size : padding_from;
  *layout = &layouts_.emplace(name, std::move(made)).first->second;
  return Status::Ok();
}

}  // namespace calibd::server::ulog
