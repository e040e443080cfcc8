// Spreadsheet exports (';' or tab separators, decimal commas) through the real server and the
// command line: a 400 / exit 2 whose message says what was found, where, and what to change.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/lib/test_paths.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TempDir;
using testing::TestServer;

constexpr const char* kAdvice =
    "calibd reads comma-separated files; export as CSV with ',' as the separator and '.' as the "
    "decimal mark";

TEST(SpreadsheetCsv, SemicolonUploadGetsA400NamingLineColumnAndTheFix) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const std::string csv = "position;s1;s2;s3\np1;1,0;0,0;0,0\np2;0,0;1,0;0,0\n";
  auto res = server.Client().Post("/api/v1/recordings?method=pca&device=SN-1", csv, "text/csv");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  const json error = json::parse(res->body)["error"];
  EXPECT_EQ(error["message"],
            std::string("line 1 uses ';' as the separator (first at character 9): ") + kAdvice +
                ", or read it as it is with the config key delimiter \";\" (and decimal \",\" "
                "if its numbers have decimal commas)");
  EXPECT_EQ(error["line"], 1);
  EXPECT_EQ(error["column"], 1);
  // Nothing was stored.
  auto list = server.Client().Get("/api/v1/jobs");
  ASSERT_TRUE(list);
  EXPECT_TRUE(json::parse(list->body)["jobs"].empty());

  const std::string decimal_comma = "position,s1,s2,s3\np1,\"1,5\",0,0\n";
  res = server.Client().Post("/api/v1/recordings?method=pca", decimal_comma, "text/csv");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400);
  EXPECT_EQ(json::parse(res->body)["error"]["message"],
            std::string("line 2 uses ',' as the decimal mark ('1,5' in column 's1'; write 1.5): ") +
                kAdvice);
}

TEST(SpreadsheetCsv, TabSeparatedFileMakesCalibrateExitTwoWithTheMessage) {
  TempDir dir;
  const std::string csv = (dir.path() / "sheet.csv").string();
  const std::string config = (dir.path() / "config.json").string();
  std::ofstream(csv) << "position\ts1\ts2\ts3\np1\t1.0\t0\t0\n";
  std::ofstream(config) << R"({"method": "pca"})";
  FILE* pipe = ::popen((calibd::test_paths::CalibdBinary() + " calibrate " + csv + " --config " +
                        config + " 2>&1 >/dev/null")
                           .c_str(),
                       "r");
  ASSERT_NE(pipe, nullptr);
  std::string err;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) err.append(buf, n);
  const int status = ::pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2) << err;
  EXPECT_NE(err.find("line 1 uses a tab as the separator (first at character 9): " +
                     std::string(kAdvice)),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("sheet.csv"), std::string::npos) << err;
}

}  // namespace
}  // namespace calibd::server
