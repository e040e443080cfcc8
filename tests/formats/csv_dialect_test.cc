// Config columns/delimiter/decimal (formats/csv_dialect.h) through the recording parser: a
// foreign CSV reads as calibd's own, and every error names the key, line and column.
#include "formats/csv_dialect.h"

#include <gtest/gtest.h>

#include "formats/recording.h"

namespace calibd::server {
namespace {

using nlohmann::json;

Status Parse(const std::string& text, const json& config, ArrayRecording* out,
             RecordingSummary* summary = nullptr, bool one_pass = true) {
  CsvDialect dialect;
  Status s = ParseCsvDialect(config, &dialect);
  if (!s.ok()) return s;
  RecordingLimits limits;
  limits.one_pass_rows = one_pass;
  RecordingParser parser("phone.csv", /*collect=*/true, limits);
  parser.SetCsvDialect(dialect);
  parser.SetTimeUnit(TimeUnit::kMilliseconds);
  s = ParseRecording(text, &parser);
  if (!s.ok()) return s;
  if (summary != nullptr) *summary = parser.summary();
  return parser.TakeArray(out);
}

const json kPhone = {{"delimiter", ";"},
                     {"decimal", ","},
                     {"columns",
                      {{"t", "time_ms"},
                       {"a0_x", "accX"},
                       {"a0_y", "accY"},
                       {"a0_z", "accZ"},
                       {"g0_x", "gyrX"},
                       {"g0_y", "gyrY"},
                       {"g0_z", "gyrZ"}}}};

TEST(CsvDialect, PhoneAppFileReadsAsCalibdsOwnOnBothRowReaders) {
  const std::string phone =
      "time_ms;gyrX;gyrY;gyrZ;note;accX;accY;accZ\n"
      "0;0,5;-1,25;2e-3;walk, fast;9,81;0;-0,5\n"
      "10,5;1;2;3;x;4;5;6\n";
  const std::string own =
      "t,g0_x,g0_y,g0_z,a0_x,a0_y,a0_z\n"
      "0,0.5,-1.25,2e-3,9.81,0,-0.5\n"
      "10.5,1,2,3,4,5,6\n";
  ArrayRecording expected;
  ASSERT_TRUE(Parse(own, json::object(), &expected).ok());
  for (bool one_pass : {true, false}) {
    ArrayRecording got;
    RecordingSummary summary;
    Status s = Parse(phone, kPhone, &got, &summary, one_pass);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_EQ(got.accel, expected.accel);
    EXPECT_EQ(got.gyro, expected.gyro);
    EXPECT_EQ(got.t, expected.t);
    EXPECT_DOUBLE_EQ(got.t(1), 0.0105);  // time_unit ms applies to the mapped column
    const json read = json::parse(summary.log_description);
    EXPECT_EQ(read["csv"]["columns"]["a0_x"], "accX");
    EXPECT_EQ(read["csv"]["ignored"], json::array({"note"}));
    ASSERT_EQ(read["warnings"].size(), 1u);  // once, listing the ignored columns
    EXPECT_NE(read["warnings"][0].get<std::string>().find("'note'"), std::string::npos);
    EXPECT_EQ(summary.columns[0], "time_ms");  // the file's names, as uploaded
  }
}

TEST(CsvDialect, TabDelimiterAndPcaPositionMapping) {
  CsvDialect dialect;
  ASSERT_TRUE(
      ParseCsvDialect({{"delimiter", "\t"}, {"columns", {{"position", "Pos"}}}}, &dialect).ok());
  RecordingParser parser("tab.csv", true);
  parser.SetCsvDialect(dialect);
  ASSERT_TRUE(ParseRecording("Pos\ts1\ts2\np,1\t1.5\t2\n", &parser).ok());
  PcaRecording pca;
  ASSERT_TRUE(parser.TakePca(&pca).ok());
  EXPECT_EQ(pca.position_labels[0], "p,1");
  EXPECT_EQ(pca.readings(0, 0), 1.5);
}

TEST(CsvDialect, ErrorsNameTheKeyLineAndColumn) {
  ArrayRecording out;
  struct Case {
    std::string text;
    json config;
    std::string field;
    int64_t line, column;
    std::string says;
  } cases[] = {
      {"time_ms;accX;accY\n", kPhone, "columns.a0_z", 1, 0,
       "'accZ', which the header does not have"},
      {"t,a0_x,a0_y,a0_z,accX\n0,1,2,3,4\n",
       {{"columns", {{"a0_x", "accX"}}}},
       "columns.a0_x",
       1,
       2,
       "the header already has a column 'a0_x'"},
      {"x,accX,accX\n", {{"columns", {{"a0_x", "accX"}}}}, "columns.a0_x", 1, 3, "twice"},
      {"",
       {{"columns", {{"a0_x", "accX"}, {"a1_x", "accX"}}}},
       "columns.a1_x",
       0,
       0,
       "both name the file's column 'accX'"},
      {"", {{"columns", {{"speed", "v"}}}}, "columns.speed", 0, 0, "not a calibd column name"},
      {"", {{"columns", {{"t", 3}}}}, "columns.t", 0, 0, "non-empty string"},
      {"", {{"decimal", ","}}, "decimal", 0, 0, "needs a 'delimiter' other than"},
      {"", {{"delimiter", "|"}}, "delimiter", 0, 0, "must be"},
      {"time_ms;accX;accY;accZ;gyrX;gyrY;gyrZ\n0;1;2;3;4;5;x,5\n", kPhone, "gyrZ", 2, 7,
       "is not a number"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.config.dump() + " " + c.text);
    Status s = Parse(c.text, c.config, &out);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.field(), c.field);
    EXPECT_EQ(s.line(), c.line);
    EXPECT_EQ(s.column(), c.column);
    EXPECT_NE(s.message().find(c.says), std::string::npos) << s.message();
  }
}

TEST(CsvDialect, WithoutConfigForeignFilesKeepTheirClearErrors) {
  ArrayRecording out;
  Status s = Parse("time_ms;accX\n0;1\n", json::object(), &out);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("delimiter \";\""), std::string::npos) << s.message();
  s = Parse("time_ms,accX\n0,1\n", json::object(), &out);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("unknown column 'time_ms'"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::server
