#include "server/device_lookup.h"

#include <vector>

namespace calibd::server {

namespace {

bool EqualIgnoringAsciiCase(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    char x = a[i], y = b[i];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

}  // namespace

std::string WrongCaseDeviceMessage(storage::Store* store, const std::string& serial) {
  std::vector<storage::DeviceInfo> devices;
  if (!store->ListDevices(&devices).ok()) return "";
  const storage::DeviceInfo* near = nullptr;
  for (const auto& d : devices) {
    if (d.serial == serial) return "";
    if (near == nullptr && EqualIgnoringAsciiCase(d.serial, serial)) near = &d;
  }
  if (near == nullptr) return "";
  return "no device '" + serial + "'; did you mean '" + near->serial + "'?";
}

}  // namespace calibd::server
