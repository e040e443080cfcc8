// Percent-encoding of a URL component (RFC 3986: unreserved characters kept), for links in pages
// and Location headers.
#ifndef CALIBD_BASE_URL_H_
#define CALIBD_BASE_URL_H_

#include <string>
#include <string_view>

namespace calibd {

// Every byte but A-Z a-z 0-9 - _ . ~ as %XX (upper-case hex): safe in a path segment and in a
// query value.
std::string UrlEncode(std::string_view s);

}  // namespace calibd

#endif  // CALIBD_BASE_URL_H_
