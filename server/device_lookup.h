// Device serials are matched exactly (case matters: "SN-0001" and "sn-0001" are two devices). A
// lookup that finds nothing under the exact serial names a stored serial that differs only in
// case, so a 404 says what was probably meant.
#ifndef CALIBD_SERVER_DEVICE_LOOKUP_H_
#define CALIBD_SERVER_DEVICE_LOOKUP_H_

#include <string>

#include "storage/store.h"

namespace calibd::server {

// "no device 'sn-0001'; did you mean 'SN-0001'?" when `serial` is not a stored device but one
// differing only in ASCII case is (the first of them in the store's order); "" otherwise (also
// when the store cannot be read: the caller's own message then stands).
std::string WrongCaseDeviceMessage(storage::Store* store, const std::string& serial);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_DEVICE_LOOKUP_H_
