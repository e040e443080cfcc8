// ArduPilot DataFlash messages: FMT definitions and field decoding (formats/dataflash_format.h).
#include "formats/dataflash_format.h"

#include <cmath>
#include <cstring>

namespace calibd::server::dataflash {

int FieldBytes(char c) {
  switch (c) {
    case 'b':
    case 'B':
    case 'M':
      return 1;
    case 'h':
    case 'H':
    case 'c':
    case 'C':
    case 'g':
      return 2;
    case 'i':
    case 'I':
    case 'e':
    case 'E':
    case 'L':
    case 'f':
    case 'n':
      return 4;
    case 'q':
    case 'Q':
    case 'd':
      return 8;
    case 'N':
      return 16;
    case 'Z':
    case 'a':
      return 64;
    default:
      return 0;
  }
}

bool IsIntegerField(char c) { return std::strchr("bBMhHiIqQ", c) != nullptr && c != '\0'; }

int MessageFormat::FieldIndex(std::string_view label) const {
  for (size_t i = 0; i < labels.size(); ++i)
    if (labels[i] == label) return static_cast<int>(i);
  return -1;
}

namespace {

// Little-endian loads (the log's byte order) that do not depend on the host's.
uint64_t LoadLe(const uint8_t* p, int bytes) {
  uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

// A char[n] field up to its first NUL.
std::string FixedText(const uint8_t* p, size_t n) {
  const void* nul = std::memchr(p, 0, n);
  const size_t len = nul ? static_cast<size_t>(static_cast<const uint8_t*>(nul) - p) : n;
  return std::string(reinterpret_cast<const char*>(p), len);
}

// IEEE 754 binary16 to double.
double HalfToDouble(uint16_t h) {
  const int sign = (h >> 15) ? -1 : 1;
  const int exponent = (h >> 10) & 0x1F;
  const int mantissa = h & 0x3FF;
  if (exponent == 0) return sign * std::ldexp(mantissa, -24);
  if (exponent == 31) return mantissa ? std::nan("") : sign * HUGE_VAL;
  return sign * std::ldexp(mantissa + 1024, exponent - 25);
}

}  // namespace

bool ParseFmt(const uint8_t* payload, MessageFormat* format, std::string* why) {
  format->type = payload[0];
  format->length = payload[1];
  format->name = FixedText(payload + 2, 4);
  format->format = FixedText(payload + 6, 16);
  const std::string columns = FixedText(payload + 22, 64);
  format->labels.clear();
  if (!columns.empty()) {
    size_t start = 0;
    while (true) {
      const size_t comma = columns.find(',', start);
      format->labels.push_back(columns.substr(start, comma - start));
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  format->offsets.clear();
  int offset = kHeaderBytes;
  for (const char c : format->format) {
    const int bytes = FieldBytes(c);
    if (bytes == 0) {
      *why = "format character '" + std::string(1, c) + "' is not one ArduPilot defines";
      return false;
    }
    format->offsets.push_back(offset);
    offset += bytes;
  }
  if (offset != format->length) {
    *why = "length " + std::to_string(format->length) + " disagrees with its format \"" +
           format->format + "\" (" + std::to_string(offset) + " bytes with the header)";
    return false;
  }
  if (format->labels.size() != format->format.size()) {
    *why = std::to_string(format->labels.size()) + " column names for " +
           std::to_string(format->format.size()) + " format characters";
    return false;
  }
  return true;
}

int64_t ReadInteger(const uint8_t* p, char c) {
  switch (c) {
    case 'b':
      return static_cast<int8_t>(p[0]);
    case 'B':
    case 'M':
      return p[0];
    case 'h':
      return static_cast<int16_t>(LoadLe(p, 2));
    case 'H':
      return static_cast<uint16_t>(LoadLe(p, 2));
    case 'i':
      return static_cast<int32_t>(LoadLe(p, 4));
    case 'I':
      return static_cast<uint32_t>(LoadLe(p, 4));
    default:  // q, Q
      return static_cast<int64_t>(LoadLe(p, 8));
  }
}

double ReadScalar(const uint8_t* p, char c) {
  switch (c) {
    case 'c':
      return static_cast<int16_t>(LoadLe(p, 2)) * 0.01;
    case 'C':
      return static_cast<uint16_t>(LoadLe(p, 2)) * 0.01;
    case 'e':
      return static_cast<int32_t>(LoadLe(p, 4)) * 0.01;
    case 'E':
      return static_cast<uint32_t>(LoadLe(p, 4)) * 0.01;
    case 'L':
      return static_cast<int32_t>(LoadLe(p, 4)) * 1e-7;
    case 'g':
      return HalfToDouble(static_cast<uint16_t>(LoadLe(p, 2)));
    case 'f': {
      const auto bits = static_cast<uint32_t>(LoadLe(p, 4));
      float f;
      std::memcpy(&f, &bits, sizeof f);
      return f;
    }
    case 'd': {
      const uint64_t bits = LoadLe(p, 8);
      double d;
      std::memcpy(&d, &bits, sizeof d);
      return d;
    }
    case 'Q':
      return static_cast<double>(LoadLe(p, 8));
    default:
      return static_cast<double>(ReadInteger(p, c));
  }
}

int16_t ReadArrayElement(const uint8_t* p, int j) {
  return static_cast<int16_t>(LoadLe(p + 2 * j, 2));
}

std::string ReadText(const uint8_t* p, char c) { return FixedText(p, FieldBytes(c)); }

}  // namespace calibd::server::dataflash
