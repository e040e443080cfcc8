// The history page's device filter over real sockets (server/html_routes.cc), on one kept-alive
// connection: an exact serial lists that device only; otherwise every device whose serial starts
// with what was typed, ignoring case, is listed together and named in a hint; nothing matching
// says so. The page is always a 200 with the typed text kept in the form.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using testing::TestServer;

bool Has(const std::string& page, const std::string& needle) {
  return page.find(needle) != std::string::npos;
}

// Stores a (too small, so quickly failing) pca recording for `device`; returns its job's id.
int64_t Upload(httplib::Client& client, const std::string& device, int n) {
  const std::string csv =
      "# " + std::to_string(n) + "\nposition,s0,s1,s2\np0,1,0,0\np1,0,1,0\np2,0,0,1\n";
  auto res =
      client.Post(("/api/v1/recordings?method=pca&device=" + device).c_str(), csv, "text/csv");
  if (!res || res->status != 201) {
    ADD_FAILURE() << "upload for " << device << ": " << (res ? res->body : "no answer");
    return 0;
  }
  return nlohmann::json::parse(res->body)["job"]["id"].get<int64_t>();
}

TEST(HistoryDeviceFilter, ExactThenCaseInsensitivePrefixWithAHint) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  const int64_t a = Upload(client, "SN-0001", 1);
  const int64_t b = Upload(client, "SN-0002", 2);
  const int64_t other = Upload(client, "OTHER", 3);
  const int64_t longer = Upload(client, "SN-0001-B", 4);
  ASSERT_GT(a * b * other * longer, 0);
  const auto job = [](int64_t id) { return "href=\"/jobs/" + std::to_string(id) + "\""; };
  const auto get = [&](const std::string& path) {
    auto res = client.Get(path.c_str());
    EXPECT_TRUE(res) << path;
    if (!res) return std::string();
    EXPECT_EQ(res->status, 200) << path;
    return res->body;
  };

  // Exact: that device only (not SN-0001-B, whose serial starts with it), no hint.
  std::string page = get("/?device=SN-0001");
  EXPECT_TRUE(Has(page, job(a)));
  EXPECT_FALSE(Has(page, job(longer)));
  EXPECT_FALSE(Has(page, job(b)));
  EXPECT_FALSE(Has(page, "device-hint"));
  EXPECT_TRUE(Has(page, "1 matching calibrations."));

  // Case and prefix: the three SN-000* devices together, newest first, named in the hint.
  page = get("/?device=sn-000");
  EXPECT_TRUE(Has(page, "device-hint")) << page;
  EXPECT_TRUE(Has(page,
                  "No device is called \xE2\x80\x9Csn-000\xE2\x80\x9D: showing the 3 "
                  "devices whose serial starts with it (case ignored)"));
  for (const char* d : {"SN-0001", "SN-0002", "SN-0001-B"}) {
    EXPECT_TRUE(Has(page, std::string("<a href=\"/?device=") + d + "\">")) << d;
  }
  EXPECT_TRUE(Has(page, job(a)));
  EXPECT_TRUE(Has(page, job(b)));
  EXPECT_TRUE(Has(page, job(longer)));
  EXPECT_FALSE(Has(page, job(other)));
  EXPECT_LT(page.find(job(longer)), page.find(job(a)));
  EXPECT_TRUE(Has(page, "3 matching calibrations."));
  EXPECT_TRUE(Has(page, "name=\"device\" value=\"sn-000\""));
  // The cursor pages the merged list.
  page = get("/?device=sn-000&before=" + std::to_string(longer));
  EXPECT_TRUE(Has(page, job(a)));
  EXPECT_TRUE(Has(page, job(b)));
  EXPECT_FALSE(Has(page, job(longer)));

  // One device by a lower-case prefix.
  page = get("/?device=oth");
  EXPECT_TRUE(Has(page, "showing the device whose serial starts with it"));
  EXPECT_TRUE(Has(page, job(other)));
  EXPECT_FALSE(Has(page, job(a)));

  // Nothing matches: said, no rows.
  page = get("/?device=ZZZ");
  EXPECT_TRUE(Has(page,
                  "No device is called \xE2\x80\x9CZZZ\xE2\x80\x9D, and no device&#39;s "
                  "serial starts with it"))
      << page;
  EXPECT_TRUE(Has(page, "No calibrations match."));
}

}  // namespace
}  // namespace calibd::server
