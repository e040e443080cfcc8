// Device serials. A serial is stored in Unicode NFC and may not hold what a reader cannot see
// (invisible, bidi-control or leading/trailing white-space characters), so two serials that look
// the same are the same device or refused (NormalizeSerial). Lookups match the stored serial
// exactly (case matters: "SN-0001" and "sn-0001" are two devices); one that finds nothing names a
// stored serial that looks alike (SimilarDeviceMessage), so a 404 says what was probably meant.
#ifndef CALIBD_SERVER_DEVICE_LOOKUP_H_
#define CALIBD_SERVER_DEVICE_LOOKUP_H_

#include <string>
#include <string_view>

#include "base/status.h"
#include "base/utf8.h"
#include "storage/store.h"
#include "web/pages.h"

namespace calibd::server {

// The serial as stored: `raw` in NFC ("CAFE" + U+0301 -> "CAF" + U+00C9). kInvalidInput (field
// "device") when it is empty or longer than 128 bytes, is not UTF-8, or holds a control character,
// '/', an invisible character (Unicode default-ignorable or format: zero-width space, byte-order
// mark, soft hyphen, ...), a bidi control, a line or paragraph separator, white space other than
// U+0020 SPACE, or white space at its start or end; the message names the character (U+XXXX and
// its Unicode name) and its position (character N of the serial, counted from 1).
Status NormalizeSerial(std::string_view raw, std::string* out);

// For a lookup of `serial` that found nothing: "no device 'CAFE'; did you mean 'CAFÉ'? ..." naming
// the first stored serial (in the store's order) that differs from it but looks alike: equal
// LookAlikeKey (base/utf8.h: case, invisible and edge white-space characters, Unicode TR39
// confusables), with the first character where they differ. "" when `serial` is stored, when no
// stored serial looks alike, or when the store cannot be read (the caller's own message then
// stands). Reads the devices a page at a time (bounded memory).
std::string SimilarDeviceMessage(storage::Store* store, const std::string& serial);

// The history page's device filter: web::MatchDevices's rule over the stored serials, reading a
// bounded number of them (not every device): the exact serial when stored (exact = true);
// else the serials starting with `typed` ignoring ASCII case, in byte order, at most `limit`
// listed and the rest counted in `more`. Each case variant of `typed` is one range of the
// serials' index; a skip scan reads those ranges (and at most one page between two of them),
// at most `max_reads` serials in all. *complete = false when it stopped there (`more` is then a
// lower bound). Empty `typed`: no match, nothing read.
Status MatchStoredDevices(storage::Store* store, const std::string& typed, size_t limit,
                          size_t max_reads, web::DeviceMatch* out, bool* complete);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_DEVICE_LOOKUP_H_
