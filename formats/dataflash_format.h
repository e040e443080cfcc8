// ArduPilot DataFlash messages (the `.bin` log; formats/dataflash.h reads the sensor streams from
// it): the message framing, FMT definitions, format characters and field decoding, as ArduPilot
// documents them (libraries/AP_Logger/LogStructure.h) and its tools read them (pymavlink
// DFReader).
//
// A log is a sequence of messages, each `0xA3 0x95 type payload`, the whole message `length`
// bytes long. FMT messages (type 128, 89 bytes) define the others: type, length, a name of up to
// 4 characters, up to 16 format characters (one per field, below) and the field names,
// comma-separated in up to 64 characters. Little-endian, packed.
#ifndef CALIBD_FORMATS_DATAFLASH_FORMAT_H_
#define CALIBD_FORMATS_DATAFLASH_FORMAT_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace calibd::server::dataflash {

inline constexpr uint8_t kHead1 = 0xA3;
inline constexpr uint8_t kHead2 = 0x95;
inline constexpr int kHeaderBytes = 3;  // kHead1, kHead2, type
inline constexpr uint8_t kFmtType = 128;
inline constexpr int kFmtLength =
    89;  // 3 + type, length (1 + 1) + name, format, labels (4 + 16 + 64)

// Bytes of one field of format character `c`, or 0 for a character ArduPilot does not define:
//   b int8, B uint8, M uint8 (flight mode), h int16, H uint16, c int16 ×0.01, C uint16 ×0.01,
//   g float16, i int32, I uint32, e int32 ×0.01, E uint32 ×0.01, L int32 ×1e-7 (degrees of
//   latitude or longitude), f float, q int64, Q uint64, d double, n char[4], N char[16],
//   Z char[64], a int16[32].
int FieldBytes(char c);
// True for the characters that hold an integer without a scale (b B M h H i I q Q).
bool IsIntegerField(char c);

// One message type as a FMT message defines it. Value type.
struct MessageFormat {
  uint8_t type = 0;
  int length = 0;                   // whole message, header included
  std::string name;                 // "IMU", "MAG", ...
  std::string format;               // one character per field
  std::vector<std::string> labels;  // one per field
  std::vector<int> offsets;         // byte offset of each field from the message start

  // The index of field `label`, or -1.
  int FieldIndex(std::string_view label) const;
};

// Parses the payload of a FMT message (the kFmtLength - kHeaderBytes bytes after the header)
// into *format. On failure returns false and sets *why ("length 12 is less than ..."): a format
// character ArduPilot does not define, a length that is not 3 + the fields' bytes, or a number of
// labels different from the number of format characters.
bool ParseFmt(const uint8_t* payload, MessageFormat* format, std::string* why);

// The value of a field `c` holding one number (all but n, N, Z and a) at `p`, scaled (c/C/e/E
// ×0.01, L ×1e-7).
double ReadScalar(const uint8_t* p, char c);
// The value of integer field `c` (IsIntegerField) at `p`; uint64 values above INT64_MAX come back
// negative (callers range-check).
int64_t ReadInteger(const uint8_t* p, char c);
// Element j (0..31) of an `a` field (int16[32]) at `p`.
int16_t ReadArrayElement(const uint8_t* p, int j);
// A char[N] field (n, N, Z) at `p` up to its first NUL.
std::string ReadText(const uint8_t* p, char c);

}  // namespace calibd::server::dataflash

#endif  // CALIBD_FORMATS_DATAFLASH_FORMAT_H_
