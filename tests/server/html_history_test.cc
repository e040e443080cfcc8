// The HTML pages over real sockets, on one kept-alive connection. The history's device filter
// (server/html_routes.cc): an exact serial lists that device only; otherwise every device whose
// serial starts with what was typed, ignoring case, is listed together and named in a hint;
// nothing matching says so; the page is always a 200 with the typed text kept in the form. The
// recording page (server/recording_routes.cc) says which units its timelines are in.
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
  EXPECT_FALSE(Has(page, "class=\"callout device-hint\""));
  EXPECT_TRUE(Has(page, "1 matching calibrations."));

  // Case and prefix: the three SN-000* devices together, newest first, named in the hint.
  page = get("/?device=sn-000");
  EXPECT_TRUE(Has(page, "class=\"callout device-hint\"")) << page;
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

// The recording page of a log in counts (|a| of about 5500 at rest): the timelines say reading
// units, not m/s², until the query gives the units.
TEST(RecordingPageUnits, ACountLogIsLabelledReadingUnitsUntilTheUnitsAreGiven) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  for (int i = 0; i < 1500; ++i) {  // 15 s at 100 Hz, still, with a little noise
    const int n = (i * 7919) % 13 - 6;
    csv += std::to_string(i / 100.0) + "," + std::to_string(3 + n) + "," + std::to_string(-2 - n) +
           "," + std::to_string(5500 + n) + "," + std::to_string(n) + "," + std::to_string(-n) +
           ",1\n";
  }
  auto res = client.Post("/api/v1/recordings?method=noise&device=COUNTS", csv, "text/csv");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  const std::string id =
      std::to_string(nlohmann::json::parse(res->body)["recording"]["id"].get<int64_t>());
  res = client.Get(("/recordings/" + id).c_str());
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200);
  EXPECT_TRUE(Has(res->body, "|a| (reading units)")) << res->body.substr(0, 3000);
  EXPECT_FALSE(Has(res->body, "|a| (m/s\xC2\xB2)"));
  EXPECT_TRUE(Has(res->body, "The accelerometer norm at rest is 5500"));
  res = client.Get(("/recordings/" + id + "?accel_unit=0.001783&gyro_unit=0.001").c_str());
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200);
  EXPECT_TRUE(Has(res->body, "|a| (m/s\xC2\xB2)"));
  EXPECT_TRUE(Has(res->body, "|\xCF\x89| (rad/s)"));
  EXPECT_FALSE(Has(res->body, "units-note"));
  // Units given that do not fit the log: labelled as given, and questioned.
  res = client.Get(("/recordings/" + id + "?accel_unit=1&gyro_unit=1").c_str());
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200);
  EXPECT_TRUE(Has(res->body, "|a| (m/s\xC2\xB2)"));
  EXPECT_TRUE(Has(res->body,
                  "With the accel_unit given, the accelerometer norm at rest is 5500 "
                  "m/s\xC2\xB2, not about 9.81: check accel_unit."));
}

}  // namespace
}  // namespace calibd::server
