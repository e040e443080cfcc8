// The HTML pages over real sockets, on one kept-alive connection. The history's device filter
// (server/html_routes.cc): an exact serial lists that device only; otherwise every device whose
// serial starts with what was typed, ignoring case, is listed together and named in a hint;
// nothing matching says so; the page is always a 200 with the typed text kept in the form. The
// recording page (server/recording_routes.cc) says which units its timelines are in.
#include <gtest/gtest.h>

#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "server/device_lookup.h"
#include "storage/db.h"
#include "storage/store.h"
#include "tests/server/http_test_util.h"
#include "web/pages.h"

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

// A database (made by the Store) holding `serials` as known devices, inserted in one transaction
// into the devices table as the Store's uploads remember them (thousands in well under a second;
// an upload each would fsync each).
void StoreDevices(const std::string& db, const std::vector<std::string>& serials) {
  {
    std::unique_ptr<storage::Store> store;
    ASSERT_TRUE(storage::Store::Open(db, storage::StoreOptions(), &store).ok());
  }
  std::unique_ptr<storage::Db> conn;
  ASSERT_TRUE(storage::Db::Open(db, storage::Db::Options(), &conn).ok());
  ASSERT_TRUE(conn->Exec("BEGIN").ok());
  for (const std::string& serial : serials) {
    storage::Stmt st;
    ASSERT_TRUE(conn->Prepare("INSERT INTO devices (serial, first_seen) VALUES (?1, 1)", &st).ok());
    st.BindText(1, serial);
    ASSERT_TRUE(st.Run().ok()) << serial;
  }
  ASSERT_TRUE(conn->Exec("COMMIT").ok());
}

// MatchStoredDevices (a skip scan over the case variants of what was typed, a bounded number of
// serials read) finds what web::MatchDevices finds in the list of every serial, on random
// serials of few letters in either case, digits, '-' and a non-ASCII letter.
TEST(HistoryDeviceFilter, TheBoundedSearchFindsWhatMatchingEverySerialFinds) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  std::mt19937 rng(27);
  const std::vector<std::string> alphabet = {"a", "A", "b", "B", "-", "1", "Ã©"};
  auto random_text = [&](int max_length) {
    std::string text;
    const int length = 1 + static_cast<int>(rng() % static_cast<unsigned>(max_length));
    for (int i = 0; i < length; ++i) text += alphabet[rng() % alphabet.size()];
    return text;
  };
  std::set<std::string> serials;
  while (serials.size() < 300) serials.insert(random_text(5));
  StoreDevices(db, std::vector<std::string>(serials.begin(), serials.end()));
  std::unique_ptr<storage::Store> store;
  ASSERT_TRUE(storage::Store::Open(db, storage::StoreOptions(), &store).ok());
  const std::vector<std::string> known(serials.begin(), serials.end());  // byte order
  int matched = 0;
  for (int trial = 0; trial < 400; ++trial) {
    const std::string typed = random_text(3);
    SCOPED_TRACE(typed);
    const web::DeviceMatch want = web::MatchDevices(typed, known, 5);
    web::DeviceMatch got;
    bool complete = false;
    ASSERT_TRUE(MatchStoredDevices(store.get(), typed, 5, 100000, &got, &complete).ok());
    EXPECT_TRUE(complete);
    EXPECT_EQ(got.exact, want.exact);
    EXPECT_EQ(got.devices, want.devices);
    EXPECT_EQ(got.more, want.more);
    if (!want.devices.empty() && !want.exact) ++matched;
    // Fewer reads: the same first devices, and complete only when all were counted.
    ASSERT_TRUE(MatchStoredDevices(store.get(), typed, 5, 3, &got, &complete).ok());
    if (!want.exact && want.devices.size() + want.more > 3) EXPECT_FALSE(complete);
    if (complete) EXPECT_EQ(got.more, want.more);
    EXPECT_LE(got.devices.size() + got.more, 3u + (want.exact ? 1u : 0u));
    for (size_t i = 0; i < got.devices.size(); ++i) EXPECT_EQ(got.devices[i], want.devices[i]);
  }
  EXPECT_GT(matched, 100);  // the trials did exercise prefixes
}

// Thousands of devices: the field offers the first 200 serials, the filter still finds every
// device of a prefix (the 20 first listed, the rest counted), and a prefix with more devices than
// the search reads says "at least".
TEST(HistoryDeviceFilter, WithThousandsOfDevicesThePageStaysCorrectAndTheListBounded) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  std::vector<std::string> serials;
  for (int i = 0; i < 3000; ++i) {
    char serial[16];
    std::snprintf(serial, sizeof serial, "SN-%04d", i);
    serials.push_back(serial);
  }
  for (const char* odd : {"sn-0050x", "Sn-0051y", "SN-0X", "OTHER"}) serials.push_back(odd);
  StoreDevices(db, serials);
  TestServer server(ServeOptions(), db);
  ASSERT_EQ(server.error(), "");
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  const auto get = [&](const std::string& path) {
    auto res = client.Get(path.c_str());
    EXPECT_TRUE(res) << path;
    if (!res) return std::string();
    EXPECT_EQ(res->status, 200) << path;
    return res->body;
  };
  const auto count = [](const std::string& page, const std::string& needle) {
    size_t n = 0;
    for (size_t at = page.find(needle); at != std::string::npos; at = page.find(needle, at + 1))
      ++n;
    return n;
  };
  std::string page = get("/");
  const size_t list = page.find("<datalist id=\"devices\">");
  ASSERT_NE(list, std::string::npos);
  const std::string offered = page.substr(list, page.find("</datalist>", list) - list);
  EXPECT_EQ(count(offered, "<option "), 200u) << "the field offers the first 200";
  EXPECT_TRUE(Has(page, "<option value=\"OTHER\">"));  // 'O' < 'S': among the first
  EXPECT_FALSE(Has(page, "<option value=\"SN-0200\">"));

  // sn-005: SN-0050..SN-0059 and the two odd ones between them, case ignored; not SN-0X.
  page = get("/?device=sn-005");
  EXPECT_TRUE(Has(page, "showing the 12 devices whose serial starts with it")) << page;
  for (const char* d : {"SN-0050", "SN-0059", "Sn-0051y", "sn-0050x"}) {
    EXPECT_TRUE(Has(page, std::string("<a href=\"/?device=") + d + "\">")) << d;
  }
  page = get("/?device=sn-00");  // 100 + 2 devices: 20 listed, 82 counted
  EXPECT_TRUE(Has(page, "showing the 20 first devices whose serial starts with it")) << page;
  EXPECT_TRUE(Has(page, " 82 more devices match")) << page;
  page = get("/?device=sN-");  // 3002 devices: more than the search reads
  EXPECT_TRUE(Has(page, "showing the 20 first devices")) << page;
  EXPECT_TRUE(Has(page, "At least 980 more devices match")) << page;
  page = get("/?device=SN-2999");  // exact, past the offered ones
  EXPECT_FALSE(Has(page, "class=\"callout device-hint\""));
  page = get("/?device=SN-3");  // nothing: the hint
  EXPECT_TRUE(Has(page, "no device&#39;s serial starts with it")) << page;
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
