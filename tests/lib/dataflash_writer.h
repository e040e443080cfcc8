// A small ArduPilot DataFlash writer for tests, the fuzz seeds and the benchmark: FMT messages
// and data messages from their format characters (formats/dataflash_format.h), written as
// ArduPilot's AP_Logger lays them out (0xA3 0x95 type, fields packed little-endian). Numbers are
// given in the field's meaning and encoded by its scale (c ×0.01: 12.34 is stored as 1234).
// Header-only (the bench links no test library). Not thread-safe.
#ifndef CALIBD_TESTS_LIB_DATAFLASH_WRITER_H_
#define CALIBD_TESTS_LIB_DATAFLASH_WRITER_H_

#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <type_traits>
#include <vector>

#include "formats/dataflash_format.h"

namespace calibd::testing {

namespace dataflash = calibd::server::dataflash;

// One field's value: a number, or text for n/N/Z, or 32 numbers for `a`.
struct DfField {
  double number = 0;
  std::string text;
  std::vector<int16_t> array;
  template <typename T, typename = std::enable_if_t<std::is_arithmetic_v<T>>>
  DfField(T v) : number(static_cast<double>(v)) {}          // NOLINT: implicit by design
  DfField(const char* t) : text(t) {}                       // NOLINT
  DfField(std::vector<int16_t> a) : array(std::move(a)) {}  // NOLINT
};

class DataFlashWriter {
 public:
  // Appends a FMT message for `type`; `length` < 0 computes it from `format` (a test passes a
  // wrong one to damage the log). Later Message() calls of `type` use this format.
  void Fmt(uint8_t type, const std::string& name, const std::string& format,
           const std::string& labels, int length = -1) {
    if (length < 0) {
      length = dataflash::kHeaderBytes;
      for (char c : format) length += dataflash::FieldBytes(c);
    }
    formats_[type] = format;
    Header(dataflash::kFmtType);
    bytes_.push_back(static_cast<char>(type));
    bytes_.push_back(static_cast<char>(length));
    Text(name, 4);
    Text(format, 16);
    Text(labels, 64);
  }
  // The FMT of FMT itself, as every ArduPilot log starts.
  void FmtOfFmt() { Fmt(dataflash::kFmtType, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"); }

  // Appends a message of `type` (defined by Fmt) with one value per format character.
  void Message(uint8_t type, const std::vector<DfField>& fields) {
    const std::string& format = formats_.at(type);
    Header(type);
    for (size_t i = 0; i < format.size(); ++i) Field(format[i], fields.at(i));
  }
  // Appends raw bytes (junk, a cut-off message).
  void Raw(const std::string& bytes) { bytes_ += bytes; }

  const std::string& bytes() const { return bytes_; }
  size_t size() const { return bytes_.size(); }

 private:
  void Header(uint8_t type) {
    bytes_.push_back(static_cast<char>(dataflash::kHead1));
    bytes_.push_back(static_cast<char>(dataflash::kHead2));
    bytes_.push_back(static_cast<char>(type));
  }
  void Text(const std::string& text, size_t n) {
    std::string padded = text.substr(0, n);
    padded.resize(n, '\0');
    bytes_ += padded;
  }
  void Le(uint64_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) bytes_.push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
  }
  void Field(char c, const DfField& f) {
    const double scale = (c == 'c' || c == 'C' || c == 'e' || c == 'E') ? 0.01
                         : c == 'L'                                     ? 1e-7
                                                                        : 1;
    const double stored = std::round(f.number / scale);
    switch (c) {
      case 'f': {
        const float v = static_cast<float>(f.number);
        uint32_t bits;
        std::memcpy(&bits, &v, sizeof bits);
        return Le(bits, 4);
      }
      case 'd': {
        uint64_t bits;
        std::memcpy(&bits, &f.number, sizeof bits);
        return Le(bits, 8);
      }
      case 'n':
      case 'N':
      case 'Z':
        return Text(f.text, dataflash::FieldBytes(c));
      case 'a':
        for (int j = 0; j < 32; ++j)
          Le(static_cast<uint16_t>(j < static_cast<int>(f.array.size()) ? f.array[j] : 0), 2);
        return;
      case 'Q':
        return Le(static_cast<uint64_t>(stored), 8);
      default:  // signed and unsigned integers of 1 to 8 bytes (two's complement)
        return Le(static_cast<uint64_t>(static_cast<int64_t>(stored)), dataflash::FieldBytes(c));
    }
  }

  std::string bytes_;
  std::map<uint8_t, std::string> formats_;
};

// Message types and formats as ArduPilot 4.x logs them.
inline constexpr uint8_t kDfImu = 163, kDfMag = 113, kDfFmtu = 118, kDfUnit = 119, kDfMult = 120,
                         kDfParm = 32, kDfAcc = 170, kDfIsbh = 164, kDfIsbd = 165;
inline void WriteArduPilotFormats(DataFlashWriter* w) {
  w->FmtOfFmt();
  w->Fmt(kDfFmtu, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds");
  w->Fmt(kDfUnit, "UNIT", "QbZ", "TimeUS,Id,Label");
  w->Fmt(kDfMult, "MULT", "Qbd", "TimeUS,Id,Mult");
  w->Fmt(kDfParm, "PARM", "QNff", "TimeUS,Name,Value,Default");
  w->Fmt(kDfImu, "IMU", "QBffffffIIfBBHH",
         "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz");
  w->Fmt(kDfMag, "MAG", "QBhhhhhhhhhBI",
         "TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOX,MOY,MOZ,Health,S");
  w->Fmt(kDfAcc, "ACC", "QBQfff", "TimeUS,I,SampleUS,AccX,AccY,AccZ");
  w->Fmt(kDfIsbh, "ISBH", "QHBBHHQf", "TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate");
  w->Fmt(kDfIsbd, "ISBD", "QHHaaa", "TimeUS,N,seqno,x,y,z");
}
// IMU: gyro, accel (m/s²), temperature.
inline void WriteImu(DataFlashWriter* w, uint64_t time_us, int instance, const double gyro[3],
                     const double accel[3], double temp) {
  w->Message(kDfImu, {time_us, instance, gyro[0], gyro[1], gyro[2], accel[0], accel[1], accel[2], 0,
                      0, temp, 1, 1, 1000, 1000});
}
// MAG in milligauss.
inline void WriteMag(DataFlashWriter* w, uint64_t time_us, int instance, const int mg[3]) {
  w->Message(kDfMag, {time_us, instance, mg[0], mg[1], mg[2], 0, 0, 0, 0, 0, 0, 1, time_us});
}

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_DATAFLASH_WRITER_H_
