// Serials that only look alike (issue #27): a serial is stored in NFC, and one holding what a
// reader cannot see (invisible, bidi-control, edge white-space characters) is refused naming the
// character and its position; a lookup that finds nothing names a stored serial that looks alike
// (case, Unicode TR39 confusables). And the device lists a page at a time (limit + after). The
// HTTP parts over real sockets with one kept-alive client.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "base/utf8.h"
#include "methods/pca/pca_method.h"
#include "server/device_lookup.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

TEST(SerialNames, WhatAReaderCannotSeeIsRefusedNamingTheCharacterAndItsPosition) {
  struct Case {
    std::string serial, expected;
  };
  const std::vector<Case> refused = {
      {"SN-1 ", "U+0020 SPACE at character 5 of 5: white space at the start or end"},
      {" SN-1", "U+0020 SPACE at character 1 of 5"},
      {"SN\xE2\x80\x8B-1", "U+200B ZERO WIDTH SPACE at character 3 of 5: an invisible character"},
      {"\xEF\xBB\xBFSN-1", "U+FEFF ZERO WIDTH NO-BREAK SPACE at character 1 of 5: an invisible"},
      {"SN-\xE2\x80\xAE"
       "1",
       "U+202E RIGHT-TO-LEFT OVERRIDE at character 4 of 5: a bidi control"},
      {"SN-\xE2\x81\xA6"
       "1",
       "U+2066 LEFT-TO-RIGHT ISOLATE at character 4 of 5: a bidi control"},
      {"SN\xC2\xA0"
       "1",
       "U+00A0 NO-BREAK SPACE at character 3 of 4: white space that looks like"},
      {"SN\xC2\xAD"
       "1",
       "U+00AD SOFT HYPHEN at character 3 of 4: an invisible character"},
      {"SN\t1", "U+0009 <control-0009> at character 3 of 4: a control character"},
      {"SN/1", "U+002F SOLIDUS at character 3 of 4: it separates the parts of URLs"},
      {"SN\xE2\x80\xA8"
       "1",
       "U+2028 LINE SEPARATOR at character 3 of 4"},
      {"SN-\xFF", "is not UTF-8 text (byte 4)"},
      {"", "must have 1 to 128 bytes"},
      {std::string(129, 'x'), "must have 1 to 128 bytes, not 129"},
  };
  for (const auto& c : refused) {
    std::string out = "unchanged";
    Status s = NormalizeSerial(c.serial, &out);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << c.serial;
    EXPECT_EQ(s.field(), "device") << c.serial;
    EXPECT_NE(s.message().find(c.expected), std::string::npos) << c.serial << ": " << s.message();
    EXPECT_EQ(out, "unchanged");
  }
  // Accepted, in NFC: a decomposed E + U+0301 becomes U+00C9; inner spaces, other scripts and
  // letters that only look Latin are serials (the hint, not the check, handles look-alikes).
  const std::vector<std::pair<std::string, std::string>> accepted = {
      {"CAFE\xCC\x81", "CAF\xC3\x89"},
      {"CAF\xC3\x89", "CAF\xC3\x89"},
      {"SN 0001", "SN 0001"},
      {"Drohne-\xC3\x9C\xC3\x9F-\xE6\xB8\xAC\xE8\xA9\xA6",
       "Drohne-\xC3\x9C\xC3\x9F-\xE6\xB8\xAC\xE8\xA9\xA6"},
      {"\xD0\x90"
       "BC-1",
       "\xD0\x90"
       "BC-1"},  // Cyrillic A
      {std::string(128, 'x'), std::string(128, 'x')},
  };
  for (const auto& [in, nfc] : accepted) {
    std::string out;
    Status s = NormalizeSerial(in, &out);
    EXPECT_TRUE(s.ok()) << in << ": " << s.ToString();
    EXPECT_EQ(out, nfc);
  }
}

TEST(SerialNames, LookAlikeKeysAreEqualForCaseConfusablesAndInvisiblesOnly) {
  const std::string latin = "ABC-1";
  EXPECT_EQ(LookAlikeKey("\xD0\x90"
                         "BC-1"),
            LookAlikeKey(latin));  // Cyrillic A
  EXPECT_EQ(LookAlikeKey("abc-1"), LookAlikeKey(latin));
  EXPECT_EQ(LookAlikeKey(" ABC\xE2\x80\x8B-1\t"), LookAlikeKey(latin));
  EXPECT_EQ(LookAlikeKey("ABC\xE2\x80\x90"
                         "1"),
            LookAlikeKey(latin));  // U+2010 HYPHEN
  EXPECT_NE(LookAlikeKey("ABC-2"), LookAlikeKey(latin));
  EXPECT_NE(LookAlikeKey("CAF\xC3\x89"), LookAlikeKey("CAFE"));
  EXPECT_EQ(LookAlikeKey("CAFE\xCC\x81"), LookAlikeKey("CAF\xC3\x89"));
  EXPECT_EQ(ToNfc("CAFE\xCC\x81"), "CAF\xC3\x89");
  EXPECT_EQ(DescribeCodePoint(0x410), "U+0410 CYRILLIC CAPITAL LETTER A");
}

std::string PcaCsv(uint64_t seed) {
  core::PcaSimulationOptions options;
  options.seed = seed;
  options.positions = 12;
  std::string csv;
  json config, truth;
  EXPECT_TRUE(SimulatePcaFiles(options, &csv, &config, &truth).ok());
  return csv;
}

json Body(const httplib::Result& res) {
  return res ? json::parse(res->body, nullptr, false) : json();
}

TEST(SerialNames, OverHttpSerialsAreStoredInNfcRefusedSayingWhyAndLookAlikesNamed) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  // Refused at upload (query string and JSON config), nothing stored; the connection stays.
  auto trailing = client.Post("/api/v1/recordings?device=SN-1%20", PcaCsv(1), "text/csv");
  ASSERT_TRUE(trailing);
  EXPECT_EQ(trailing->status, 400);
  EXPECT_NE(trailing->body.find("U+0020 SPACE at character 5 of 5"), std::string::npos)
      << trailing->body;
  auto zwsp = client.Post("/api/v1/recordings", httplib::MultipartFormDataItems{
                                                    {"recording", PcaCsv(2), "r.csv", "text/csv"},
                                                    {"config",
                                                     json{{"method", "pca"},
                                                          {"device",
                                                           "SN\xE2\x80\x8B"
                                                           "1"}}
                                                         .dump(),
                                                     "", "application/json"}});
  ASSERT_TRUE(zwsp);
  EXPECT_EQ(zwsp->status, 400);
  EXPECT_NE(zwsp->body.find("U+200B ZERO WIDTH SPACE at character 3"), std::string::npos)
      << zwsp->body;
  EXPECT_EQ(Body(client.Get("/api/v1/devices"))["devices"].size(), 0u);
  // Decomposed and composed CAFÉ are one device, stored composed; either form finds it.
  auto decomposed = client.Post("/api/v1/recordings?device=CAFE%CC%81", PcaCsv(3), "text/csv");
  ASSERT_TRUE(decomposed);
  EXPECT_EQ(decomposed->status, 201) << decomposed->body;
  auto composed = client.Post("/api/v1/recordings?device=CAF%C3%89", PcaCsv(4), "text/csv");
  ASSERT_TRUE(composed);
  EXPECT_EQ(composed->status, 201) << composed->body;
  json devices = Body(client.Get("/api/v1/devices"))["devices"];
  ASSERT_EQ(devices.size(), 1u) << devices.dump();
  EXPECT_EQ(devices[0]["serial"], "CAF\xC3\x89");
  for (const char* path :
       {"/api/v1/devices/CAFE%CC%81/calibration", "/api/v1/devices/CAF%C3%89/calibration"}) {
    auto res = client.Get(path);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 404);
    EXPECT_NE(res->body.find("no accepted calibration for device 'CAF\xC3\x89'"), std::string::npos)
        << path << ": " << res->body;
  }
  // A Cyrillic A where the stored serial has a Latin one: the 404 names the stored device and
  // the character that differs (API and page).
  auto latin = client.Post("/api/v1/recordings?device=ABC-1", PcaCsv(5), "text/csv");
  ASSERT_TRUE(latin);
  ASSERT_EQ(latin->status, 201) << latin->body;
  for (const char* path : {"/api/v1/devices/%D0%90BC-1/calibration", "/devices/%D0%90BC-1"}) {
    auto res = client.Get(path);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 404) << path;
    const bool html = path[1] == 'd';
    EXPECT_NE(res->body.find(html ? "did you mean &#39;ABC-1&#39;?" : "did you mean 'ABC-1'?"),
              std::string::npos)
        << path << ": " << res->body;
    EXPECT_NE(res->body.find("character 1: U+0410 CYRILLIC CAPITAL LETTER A, not U+0041 LATIN "
                             "CAPITAL LETTER A"),
              std::string::npos)
        << path << ": " << res->body;
  }
  // A stored device with no calibration gets no hint about another one.
  auto plain = client.Get("/api/v1/devices/ABC-1/calibration");
  ASSERT_TRUE(plain);
  EXPECT_EQ(plain->body.find("did you mean"), std::string::npos) << plain->body;
}

TEST(SerialNames, DeviceListsComePageByPageWithTheNextUrl) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  std::set<std::string> uploaded;
  for (int i = 0; i < 5; ++i) {
    const std::string serial = "P&" + std::to_string(i);  // '&' must survive the next URL
    auto up = client.Post(("/api/v1/recordings?device=P%26" + std::to_string(i)).c_str(),
                          PcaCsv(10 + i), "text/csv");
    ASSERT_TRUE(up);
    ASSERT_EQ(up->status, 201) << up->body;
    uploaded.insert(serial);
  }
  std::vector<std::string> seen;
  std::string url = "/api/v1/devices?limit=2";
  for (int pages = 0; pages < 10 && !url.empty(); ++pages) {
    json body = Body(client.Get(url.c_str()));
    ASSERT_TRUE(body.is_object()) << url;
    EXPECT_LE(body["devices"].size(), 2u);
    for (const auto& d : body["devices"]) seen.push_back(d["serial"]);
    url = body["next"].is_string() ? body["next"].get<std::string>() : "";
  }
  EXPECT_TRUE(url.empty());
  EXPECT_EQ(std::set<std::string>(seen.begin(), seen.end()), uploaded);
  EXPECT_EQ(seen.size(), uploaded.size());                               // none twice
  EXPECT_EQ(Body(client.Get("/api/v1/devices"))["devices"].size(), 5u);  // default 100
  for (const char* bad : {"/api/v1/devices?limit=0", "/api/v1/devices?limit=1001",
                          "/api/v1/devices?limit=x", "/api/v1/devices?page=2"}) {
    auto res = client.Get(bad);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << bad;
    EXPECT_NE(res->body.find(std::string(bad).find("page") != std::string::npos ? "page" : "limit"),
              std::string::npos)
        << bad << ": " << res->body;
  }
  // The devices page: after= starts after that serial; a full page links the next one.
  auto page = client.Get("/devices?after=P%263");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->body.find("P&amp;4"), std::string::npos);
  EXPECT_EQ(page->body.find("P&amp;3"), std::string::npos);
  EXPECT_EQ(page->body.find("More devices"), std::string::npos);  // 1 < 100: the last page
}

}  // namespace
}  // namespace calibd::server
