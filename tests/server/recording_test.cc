// Tests of the strict CSV reader for SPEC §2 recordings: both pca layouts, the array layout,
// chunk boundaries, and every bad-input case naming line and column.
#include "formats/recording.h"

#include <gtest/gtest.h>

#include <charconv>
#include <cmath>
#include <cstring>
#include <random>
#include <string>

namespace calibd::server {
namespace {

Status ParseAll(const std::string& text, RecordingParser* parser) {
  return ParseRecording(text, parser);
}

// Feeds `text` one byte at a time: the result must not depend on chunk boundaries.
Status ParseBytewise(const std::string& text, RecordingParser* parser) {
  for (char c : text) {
    Status s = parser->Feed(std::string_view(&c, 1));
    if (!s.ok()) return s;
  }
  return parser->Finish();
}

TEST(RecordingParser, ReadsAveragedPcaLayoutWithCommentsCrlfAndBom) {
  const std::string text =
      "\xEF\xBB\xBF# recorded on line 3\r\n"
      "position,s1,s2,s3\r\n"
      "p1,1.5,-2e-3,+3\r\n"
      "# a comment between rows\r\n"
      "p2, 4 ,5.0E1,6\r\n";
  RecordingParser parser("rec.csv", true);
  ASSERT_TRUE(ParseAll(text, &parser).ok());
  EXPECT_EQ(parser.summary().layout, Layout::kPcaAveraged);
  EXPECT_EQ(parser.summary().rows, 2);
  EXPECT_EQ(parser.summary().positions, 2);
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  ASSERT_EQ(rec.readings.rows(), 3);
  ASSERT_EQ(rec.readings.cols(), 2);
  EXPECT_EQ(rec.sensor_names, (std::vector<std::string>{"s1", "s2", "s3"}));
  EXPECT_EQ(rec.position_labels, (std::vector<std::string>{"p1", "p2"}));
  EXPECT_DOUBLE_EQ(rec.readings(0, 0), 1.5);
  EXPECT_DOUBLE_EQ(rec.readings(1, 0), -2e-3);
  EXPECT_DOUBLE_EQ(rec.readings(2, 0), 3);
  EXPECT_DOUBLE_EQ(rec.readings(1, 1), 50);
  EXPECT_FALSE(rec.raw);
}

TEST(RecordingParser, RawLayoutSubtractsEachPositionsStaticMean) {
  const std::string text =
      "position,phase,s1,s2\n"
      "A,static,0.1,0.2\n"
      "A,static,0.3,0.2\n"
      "A,moving,1.2,0.2\n"
      "B,moving,0.2,2.2\n"
      "B,static,0.2,0.1\n"
      "B,moving,0.2,2.4\n";
  RecordingParser parser("raw.csv", true);
  ASSERT_TRUE(ParseAll(text, &parser).ok());
  EXPECT_EQ(parser.summary().layout, Layout::kPcaRaw);
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  EXPECT_TRUE(rec.raw);
  EXPECT_NEAR(rec.readings(0, 0), 1.2 - 0.2, 1e-15);
  EXPECT_NEAR(rec.readings(1, 0), 0.0, 1e-15);
  EXPECT_NEAR(rec.readings(1, 1), 2.3 - 0.1, 1e-15);
  EXPECT_NEAR(rec.static_means(0, 0), 0.2, 1e-15);
  EXPECT_EQ(rec.static_rows, (std::vector<int64_t>{2, 1}));
  EXPECT_EQ(rec.moving_rows, (std::vector<int64_t>{1, 2}));
}

TEST(RecordingParser, ResultDoesNotDependOnChunkBoundaries) {
  std::string text = "position,phase,\"s 1\",s2\n";
  for (int p = 0; p < 20; ++p) {
    text += "p" + std::to_string(p) + ",static,0." + std::to_string(p) + ",1\n";
    text += "p" + std::to_string(p) + ",moving,1." + std::to_string(p) + ",2e" +
            std::to_string(p % 3) + "\r\n";
  }
  RecordingParser whole("a.csv", true), bytewise("a.csv", true);
  ASSERT_TRUE(ParseAll(text, &whole).ok());
  ASSERT_TRUE(ParseBytewise(text, &bytewise).ok());
  PcaRecording a, b;
  ASSERT_TRUE(whole.TakePca(&a).ok());
  ASSERT_TRUE(bytewise.TakePca(&b).ok());
  EXPECT_EQ(a.sensor_names[0], "s 1");
  EXPECT_EQ(a.readings, b.readings);
  EXPECT_EQ(a.position_labels, b.position_labels);
}

TEST(RecordingParser, ReadsArrayColumnsInAnyOrder) {
  const std::string text =
      "g0_z,a1_x,a1_y,a1_z,t,a0_x,a0_y,a0_z,g0_x,g0_y\n"
      "9,4,5,6,0.5,1,2,3,7,8\n"
      "19,14,15,16,0.6,11,12,13,17,18\n";
  RecordingParser parser("arr.csv", true);
  ASSERT_TRUE(ParseAll(text, &parser).ok());
  EXPECT_EQ(parser.summary().layout, Layout::kArray);
  EXPECT_EQ(parser.summary().sensors, (std::vector<std::string>{"a0", "a1", "g0"}));
  ArrayRecording rec;
  ASSERT_TRUE(parser.TakeArray(&rec).ok());
  ASSERT_EQ(rec.accel.rows(), 2);
  ASSERT_EQ(rec.accel.cols(), 6);
  ASSERT_EQ(rec.gyro.cols(), 3);
  for (int j = 0; j < 6; ++j) EXPECT_DOUBLE_EQ(rec.accel(0, j), j + 1);
  for (int j = 0; j < 3; ++j) EXPECT_DOUBLE_EQ(rec.gyro(1, j), 17 + j);
  ASSERT_EQ(rec.t.size(), 2);
  EXPECT_DOUBLE_EQ(rec.t(1), 0.6);
}

TEST(RecordingParser, ARowCountHintNeverChangesWhatIsRead) {
  std::string text = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  for (int n = 0; n < 50; ++n) {
    text += std::to_string(0.01 * n) + "," + std::to_string(n) + ",2,3,4,5," + std::to_string(-n) +
            "\n";
  }
  RecordingParser plain("arr.csv", true);
  ASSERT_TRUE(ParseAll(text, &plain).ok());
  ArrayRecording want;
  ASSERT_TRUE(plain.TakeArray(&want).ok());
  // Exact, too small, too large, negative: the hint only sizes the buffers.
  for (int64_t hint : {int64_t{50}, int64_t{7}, int64_t{100000}, int64_t{-3}}) {
    RecordingParser hinted("arr.csv", true);
    hinted.ExpectRows(hint);
    ASSERT_TRUE(ParseAll(text, &hinted).ok());
    ArrayRecording got;
    ASSERT_TRUE(hinted.TakeArray(&got).ok());
    EXPECT_EQ(got.accel, want.accel) << hint;
    EXPECT_EQ(got.gyro, want.gyro) << hint;
    EXPECT_EQ(got.t, want.t) << hint;
  }
}

TEST(RecordingParser, FloatCollectionHoldsEachReadingTimesItsScaleRoundedOnce) {
  // Readings with more digits than a float holds, in a column order that is not the layout's.
  std::string text = "g0_z,t,a0_x,a0_y,a0_z,g0_x,g0_y\n";
  for (int n = 0; n < 40; ++n) {
    text += std::to_string(0.1 + 1e-7 * n) + "," + std::to_string(0.0025 * n) + ",3276" +
            std::to_string(n % 10) + ".123456789,-1.000000123,9.80665432," + std::to_string(-n) +
            ".5,17.0000001\n";
  }
  const double accel_scale = 0.00239420, gyro_scale = 0.017453292519943295;
  RecordingParser plain("arr.csv", true);
  ASSERT_TRUE(ParseAll(text, &plain).ok());
  ArrayRecording want;
  ASSERT_TRUE(plain.TakeArray(&want).ok());
  // Exact, too small and no hint: straight into the matrices, spilled to the buffer, buffered.
  for (int64_t hint : {int64_t{40}, int64_t{9}, int64_t{0}}) {
    RecordingParser floats("arr.csv", true);
    floats.ExpectRows(hint);
    floats.CollectArrayAsFloat(accel_scale, gyro_scale);
    double a = 0, g = 0;
    ASSERT_TRUE(floats.collects_float(&a, &g));
    EXPECT_EQ(a, accel_scale);
    EXPECT_EQ(g, gyro_scale);
    ASSERT_TRUE(ParseAll(text, &floats).ok());
    ArrayRecording refused;
    EXPECT_EQ(floats.TakeArray(&refused).code(), StatusCode::kInternal);
    ArrayRecordingFloat got;
    ASSERT_TRUE(floats.TakeArrayFloat(&got).ok()) << hint;
    EXPECT_EQ(got.accel_names, want.accel_names);
    EXPECT_EQ(got.gyro_names, want.gyro_names);
    EXPECT_EQ(got.accel_scale, accel_scale);
    EXPECT_EQ(got.t, want.t) << hint;  // times stay double, untouched
    EXPECT_EQ(got.accel, (want.accel * accel_scale).cast<float>().eval()) << hint;
    EXPECT_EQ(got.gyro, (want.gyro * gyro_scale).cast<float>().eval()) << hint;
  }
  // Asked too late (after the header): the parser goes on with doubles and says so.
  RecordingParser late("arr.csv", true);
  ASSERT_TRUE(late.Feed(text.substr(0, 40)).ok());
  late.CollectArrayAsFloat(accel_scale, gyro_scale);
  EXPECT_FALSE(late.collects_float());
  ASSERT_TRUE(late.Feed(text.substr(40)).ok());
  ASSERT_TRUE(late.Finish().ok());
  ArrayRecording as_double;
  ASSERT_TRUE(late.TakeArray(&as_double).ok());
  EXPECT_EQ(as_double.accel, want.accel);
  RecordingParser doubles("arr.csv", true);
  EXPECT_FALSE(doubles.collects_float());
  ASSERT_TRUE(ParseAll(text, &doubles).ok());
  ArrayRecordingFloat none;
  EXPECT_EQ(doubles.TakeArrayFloat(&none).code(), StatusCode::kInternal);
}

// Magnetometer triads (SPEC §8 mag) in any column order among the other columns: held in
// double (unscaled) on every collection path, named m0.. after the gyroscopes; a log of
// magnetometers alone is an array recording too.
TEST(RecordingParser, ReadsMagnetometerColumnsBesideTheOthersOnEveryPath) {
  std::string text = "m0_y,t,a0_x,a0_y,a0_z,m1_x,m1_y,m1_z,temp0,g0_x,g0_y,g0_z,m0_z,m0_x\n";
  for (int n = 0; n < 30; ++n) {
    const std::string k = std::to_string(n);
    text += "0." + k + "," + std::to_string(0.01 * n) + ",1,2,3,-" + k + ",5,6," + k +
            ".5,7,8,9,1e-3,123456.789012" + k + "\n";
  }
  for (int64_t hint : {int64_t{30}, int64_t{7}, int64_t{0}}) {
    for (bool as_float : {false, true}) {
      SCOPED_TRACE(std::to_string(hint) + (as_float ? " float" : " double"));
      RecordingParser parser("mag.csv", true);
      parser.ExpectRows(hint);
      if (as_float) parser.CollectArrayAsFloat(2, 3);
      ASSERT_TRUE(ParseAll(text, &parser).ok());
      EXPECT_EQ(parser.summary().sensors, (std::vector<std::string>{"a0", "g0", "m0", "m1"}));
      ArrayRecording d;
      ArrayRecordingFloat f;
      ASSERT_TRUE(as_float ? parser.TakeArrayFloat(&f).ok() : parser.TakeArray(&d).ok());
      const Eigen::MatrixXd& mag = as_float ? f.mag : d.mag;
      const Eigen::MatrixXd& temp = as_float ? f.temperature : d.temperature;
      EXPECT_EQ(as_float ? f.mag_names : d.mag_names, (std::vector<std::string>{"m0", "m1"}));
      EXPECT_EQ(as_float ? f.gyro_names : d.gyro_names, (std::vector<std::string>{"g0"}));
      ASSERT_EQ(mag.rows(), 30);
      ASSERT_EQ(mag.cols(), 6);
      ASSERT_EQ(temp.cols(), 1);
      for (int n = 0; n < 30; ++n) {
        const std::string k = std::to_string(n);
        EXPECT_EQ(mag(n, 0), std::stod("123456.789012" + k));  // full double precision
        EXPECT_EQ(mag(n, 1), std::stod("0." + k));
        EXPECT_EQ(mag(n, 2), 1e-3);
        EXPECT_EQ(mag(n, 3), -n);
        EXPECT_EQ(temp(n, 0), n + 0.5);
      }
      if (!as_float) EXPECT_EQ(d.gyro(29, 2), 9);
    }
  }
  RecordingParser alone("mag.csv", true);
  ASSERT_TRUE(ParseAll("t,m0_x,m0_y,m0_z\n0,1,2,3\n0.1,4,5,6\n", &alone).ok());
  ArrayRecording rec;
  ASSERT_TRUE(alone.TakeArray(&rec).ok());
  EXPECT_EQ(rec.accel.cols(), 0);
  EXPECT_EQ(rec.mag(1, 2), 6);
}

TEST(RecordingParser, ArrayWithoutTimeColumnHasEmptyT) {
  RecordingParser parser("arr.csv", true);
  ASSERT_TRUE(ParseAll("a0_x,a0_y,a0_z\n1,2,3\n", &parser).ok());
  ArrayRecording rec;
  ASSERT_TRUE(parser.TakeArray(&rec).ok());
  EXPECT_EQ(rec.t.size(), 0);
  EXPECT_EQ(rec.gyro.cols(), 0);
}

struct BadCase {
  const char* name;
  std::string text;
  int64_t line;
  int64_t column;
  const char* message_part;
};

class RecordingParserRejects : public ::testing::TestWithParam<BadCase> {};

TEST_P(RecordingParserRejects, WithLineColumnAndReason) {
  const BadCase& c = GetParam();
  for (bool bytewise : {false, true}) {
    RecordingParser parser("bad.csv", true);
    Status s = bytewise ? ParseBytewise(c.text, &parser) : ParseAll(c.text, &parser);
    ASSERT_FALSE(s.ok()) << c.name;
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << c.name;
    EXPECT_EQ(s.file(), "bad.csv");
    EXPECT_EQ(s.line(), c.line) << c.name << ": " << s.ToString();
    EXPECT_EQ(s.column(), c.column) << c.name << ": " << s.ToString();
    EXPECT_NE(s.message().find(c.message_part), std::string::npos) << c.name << ": " << s.message();
  }
}

INSTANTIATE_TEST_SUITE_P(
    BadInput, RecordingParserRejects,
    ::testing::Values(
        BadCase{"nan", "position,s1,s2\np,1,nan\n", 2, 3, "not a finite number"},
        BadCase{"inf", "position,s1,s2\np,-inf,1\n", 2, 2, "not a finite number"},
        BadCase{"huge exponent", "position,s1\np,1e999\n", 2, 2, "out of range"},
        BadCase{"empty cell", "position,s1,s2\np,,1\n", 2, 2, "empty cell in column 's1'"},
        BadCase{"text", "position,s1,s2\np,1,abc\n", 2, 3, "not a number"},
        BadCase{"trailing junk", "position,s1\np,1.5x\n", 2, 2, "not a number"},
        BadCase{"short row", "position,s1,s2\np,1,2\nq,1\n", 3, 3, "row has 2 fields"},
        BadCase{"long row", "position,s1\np,1,2\n", 2, 3, "row has 3 fields"},
        BadCase{"duplicate sensor", "position,s1,s1\n", 1, 3, "duplicate sensor name 's1'"},
        BadCase{"empty sensor name", "position,s1,,s3\n", 1, 3, "empty sensor name"},
        BadCase{"no sensors", "position\n", 1, 0, "no sensor columns"},
        BadCase{"bad phase", "position,phase,s1\np,rest,1\n", 2, 2, "phase must be"},
        BadCase{"missing moving", "position,phase,s1\np,static,1\nq,static,1\nq,moving,2\n", 2, 1,
                "position 'p' has no moving rows"},
        BadCase{"missing static", "position,phase,s1\np,moving,1\n", 2, 1, "no static rows"},
        BadCase{"empty label", "position,s1\n,1\n", 2, 1, "empty position label"},
        BadCase{"unknown array column", "a0_x,a0_y,a0_z,pressure\n", 1, 4,
                "unknown column 'pressure'"},
        BadCase{"incomplete triad", "a0_x,a0_y,a0_z,a1_x,a1_y\n", 1, 0, "missing column 'a1_z'"},
        BadCase{"triad gap", "a0_x,a0_y,a0_z,a2_x,a2_y,a2_z\n", 1, 0, "missing column 'a1_x'"},
        BadCase{"duplicate array column", "a0_x,a0_y,a0_z,a0_x\n", 1, 4, "duplicate column"},
        BadCase{"gyro only", "g0_x,g0_y,g0_z\n", 1, 0, "no accelerometer or magnetometer columns"},
        BadCase{"incomplete magnetometer", "a0_x,a0_y,a0_z,m0_x,m0_y\n", 1, 0,
                "missing column 'm0_z'"},
        BadCase{"unterminated quote", "position,\"s1\n", 1, 2, "unterminated quoted field"},
        BadCase{"no rows", "# only a comment\nposition,s1\n", 2, 0, "no data rows"},
        BadCase{"empty file", "", 0, 0, "no header line"},
        BadCase{"invalid utf8 label", "position,s1\n\xC3(,1\n", 2, 1, "not valid UTF-8"},
        BadCase{"invalid utf8 name", "position,s\xFF\n", 1, 2, "not valid UTF-8"},
        BadCase{"overlong utf8", "position,s\xC0\xAF\n", 1, 2, "not valid UTF-8"},
        BadCase{"nul in name", std::string("position,s\0x\n", 13), 1, 2, "control character NUL"},
        BadCase{"escape in name", "position,s\x1b[31m\n", 1, 2, "control character 0x1b"},
        BadCase{"nul in label", std::string("position,s1\np\0q,1\n", 18), 2, 1,
                "control character NUL"},
        BadCase{"tab in label", "position,s1\np\tq,1\n", 2, 1, "control character TAB"},
        BadCase{"del in label", "position,s1\np\x7fq,1\n", 2, 1, "control character 0x7f"}),
    [](const ::testing::TestParamInfo<BadCase>& info) {
      std::string name = info.param.name;
      for (char& ch : name) {
        if (!isalnum(static_cast<unsigned char>(ch))) ch = '_';
      }
      return name;
    });

// Spreadsheet exports: semicolon- or tab-separated files and decimal commas are refused with
// what was detected, where, and what to change; on the header and on the first data line, in
// both layouts, with either the one-pass or the general row reader.
TEST(RecordingParser, SpreadsheetSeparatorsAndDecimalCommasSayWhatToChange) {
  const std::string advice =
      "calibd reads comma-separated files; export as CSV with ',' as the separator and '.' as "
      "the decimal mark";
  // A separator found: also the config keys that read the file as it is.
  auto read_as_is = [&](const std::string& sep) {
    return advice + ", or read it as it is with the config key delimiter \"" + sep +
           "\" (and decimal \",\" if its numbers have decimal commas)";
  };
  struct Case {
    std::string text;
    int64_t line, column;
    std::string message;
  } cases[] = {
      {"position;s1;s2;s3\np1;1,5;0;0\n", 1, 1,
       "line 1 uses ';' as the separator (first at character 9): " + read_as_is(";")},
      {"# exported\nt\ta0_x\ta0_y\ta0_z\n0\t1.5\t0\t0\n", 2, 1,
       "line 2 uses a tab as the separator (first at character 2): " + read_as_is("\\t")},
      {"position,s1,s2,s3\np1;1;0;0\n", 2, 2,
       "line 2 uses ';' as the separator (first at character 3; row has 1 fields, the header "
       "has 4): " +
           read_as_is(";")},
      {"position,s1,s2\np1,1,5,0,25\n", 2, 4,
       "row has 5 fields, the header has 3: if ',' is the decimal mark here (e.g. '1,5' for "
       "1.5), " +
           advice},
      {"position,s1,s2\np1,\"1,5\",0\n", 2, 2,
       "line 2 uses ',' as the decimal mark ('1,5' in column 's1'; write 1.5): " + advice},
      {"a0_x,a0_y,a0_z\n1,\"-0,25e-3\",2\n", 2, 2,
       "line 2 uses ',' as the decimal mark ('-0,25e-3' in column 'a0_y'; write -0.25e-3): " +
           advice},
      {"position,s1,s2\np1;1,5;2,3\n", 2, 2,
       "line 2 uses ';' as the separator ('5;2' in column 's1'): " + read_as_is(";")},
  };
  for (const Case& c : cases) {
    for (bool one_pass : {true, false}) {
      SCOPED_TRACE(c.text);
      RecordingLimits limits;
      limits.one_pass_rows = one_pass;
      RecordingParser parser("sheet.csv", true, limits);
      Status s = ParseAll(c.text, &parser);
      ASSERT_FALSE(s.ok());
      EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
      EXPECT_EQ(s.message(), c.message);
      EXPECT_EQ(s.line(), c.line);
      EXPECT_EQ(s.column(), c.column);
    }
  }
  // A ';' or a tab inside a quoted name of a comma-separated header is a name, not a separator
  // (the header has commas); the names are refused or kept by the usual rules.
  RecordingParser parser("ok.csv", true);
  EXPECT_TRUE(ParseAll("position,\"s;1\",s2\np1,1.5,2\n", &parser).ok());
}

TEST(RecordingParser, RejectsOverlongLineWithoutBufferingIt) {
  RecordingLimits limits;
  limits.max_line_bytes = 1000;
  RecordingParser parser("big.csv", false, limits);
  ASSERT_TRUE(parser.Feed("position,s1\n").ok());
  std::string chunk(600, '1');
  ASSERT_TRUE(parser.Feed("p,").ok());
  ASSERT_TRUE(parser.Feed(chunk).ok());
  Status s = parser.Feed(chunk);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.line(), 2);
  EXPECT_NE(s.message().find("longer than 1000 bytes"), std::string::npos);
  // The error is sticky.
  EXPECT_FALSE(parser.Feed("\n").ok());
  EXPECT_FALSE(parser.Finish().ok());
}

// Long digit runs go eight at a time (SWAR): integers and fractions of every length, with and
// without leading zeros, must still match std::from_chars bit for bit.
TEST(ParseDecimalFast, DigitRunsOfEveryLengthAgreeWithFromChars) {
  std::mt19937_64 rng(7);
  int fast = 0;
  for (int i = 0; i < 100000; ++i) {
    const int int_digits = static_cast<int>(rng() % 21), frac_digits = static_cast<int>(rng() % 21);
    const int zeros = static_cast<int>(rng() % 10);
    std::string text = (rng() % 2) ? "-" : "";
    text.append(zeros, '0');
    for (int d = 0; d < int_digits; ++d) text.push_back(static_cast<char>('0' + rng() % 10));
    if (frac_digits > 0 || int_digits + zeros == 0) text.push_back('.');
    for (int d = 0; d < frac_digits; ++d) text.push_back(static_cast<char>('0' + rng() % 10));
    if (int_digits + zeros + frac_digits == 0) text.push_back('0');
    double expected = 0, got = 0;
    auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), expected);
    ASSERT_EQ(ec, std::errc()) << text;
    ASSERT_EQ(ptr, text.data() + text.size()) << text;
    if (ParseDecimalFast(text, &got)) {
      ++fast;
      ASSERT_EQ(std::memcmp(&got, &expected, sizeof got), 0) << text;
    }
  }
  EXPECT_GT(fast, 20000);
  double v = 0;
  ASSERT_TRUE(ParseDecimalFast("9007199254740992", &v));  // 2^53: the largest fast mantissa
  EXPECT_EQ(v, 9007199254740992.0);
  EXPECT_FALSE(ParseDecimalFast("9007199254740993", &v));
  EXPECT_FALSE(ParseDecimalFast("12345678901234567890", &v));
}

// The prefix form stops at the first character after the number, or refuses.
TEST(ParseDecimalPrefixFast, StopsAfterTheNumber) {
  double v = 0;
  const std::string text = "-12345678.125,7";
  const char* stop = ParseDecimalPrefixFast(text.data(), text.data() + text.size(), &v);
  ASSERT_NE(stop, nullptr);
  EXPECT_EQ(*stop, ',');
  EXPECT_EQ(v, -12345678.125);
  for (const std::string odd : {",1", "-,1", "1e,2", "1e+,2", "99999999999999999999,1"}) {
    v = 7;
    EXPECT_EQ(ParseDecimalPrefixFast(odd.data(), odd.data() + odd.size(), &v), nullptr) << odd;
    EXPECT_EQ(v, 7) << odd;
  }
}

// Plain rows take the one-pass reader, rows with spaces (or any row, with one_pass_rows = false)
// the general path (Split + ParseNumber): the same numbers must give bit-identical recordings
// either way, in both layouts.
TEST(RecordingParser, OnePassAndGeneralPathsGiveIdenticalRecordings) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  auto number = [&]() {
    char buf[64];
    const int style = static_cast<int>(rng() % 4);
    const double x = normal(rng) * std::pow(10.0, static_cast<double>(rng() % 7) - 3);
    if (style == 0) std::snprintf(buf, sizeof buf, "%.9g", x);
    if (style == 1) std::snprintf(buf, sizeof buf, "%.17g", x);
    if (style == 2) std::snprintf(buf, sizeof buf, "%.6e", x);
    if (style == 3) std::snprintf(buf, sizeof buf, "%.25f", x);  // > 19 digits: from_chars
    return std::string(buf);
  };
  std::string plain_pca = "position,phase,s1,s2,s3\n", padded_pca = plain_pca;
  std::string plain_array = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n", padded_array = plain_array;
  for (int row = 0; row < 3000; ++row) {
    const std::string label = "p" + std::to_string(row / 40);
    const char* phase = (row / 20) % 2 ? "moving" : "static";
    plain_pca += label + "," + phase;
    padded_pca += label + "," + phase;
    for (int i = 0; i < 3; ++i) {
      const std::string x = number();
      plain_pca += "," + x;
      padded_pca += ", " + x + " ";
    }
    plain_pca += "\n";
    padded_pca += "\n";
    for (int i = 0; i < 7; ++i) {
      const std::string x = number();
      plain_array += (i ? "," : "") + x;
      padded_array += (i ? ", " : " ") + x + " ";
    }
    plain_array += "\n";
    padded_array += "\n";
  }
  auto bits_equal = [](const auto& a, const auto& b) {
    return a.rows() == b.rows() && a.cols() == b.cols() &&
           std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
  };
  RecordingLimits one_pass, general;
  general.one_pass_rows = false;
  // Parses `a` with limits `la` and `b` with `lb`; the recordings must be the same, bit for bit.
  auto expect_same_pca = [&](const std::string& a, RecordingLimits la, const std::string& b,
                             RecordingLimits lb) {
    RecordingParser pa("a.csv", true, la), pb("b.csv", true, lb);
    ASSERT_TRUE(ParseAll(a, &pa).ok());
    ASSERT_TRUE(ParseAll(b, &pb).ok());
    PcaRecording ra, rb;
    ASSERT_TRUE(pa.TakePca(&ra).ok());
    ASSERT_TRUE(pb.TakePca(&rb).ok());
    EXPECT_TRUE(bits_equal(ra.readings, rb.readings));
    EXPECT_TRUE(bits_equal(ra.static_means, rb.static_means));
    EXPECT_EQ(ra.position_labels, rb.position_labels);
    EXPECT_EQ(ra.rows_per_position, rb.rows_per_position);
  };
  auto expect_same_array = [&](const std::string& a, RecordingLimits la, const std::string& b,
                               RecordingLimits lb) {
    RecordingParser pa("a.csv", true, la), pb("b.csv", true, lb);
    ASSERT_TRUE(ParseAll(a, &pa).ok());
    ASSERT_TRUE(ParseAll(b, &pb).ok());
    ArrayRecording ra, rb;
    ASSERT_TRUE(pa.TakeArray(&ra).ok());
    ASSERT_TRUE(pb.TakeArray(&rb).ok());
    EXPECT_TRUE(bits_equal(ra.accel, rb.accel));
    EXPECT_TRUE(bits_equal(ra.gyro, rb.gyro));
    EXPECT_TRUE(bits_equal(ra.t, rb.t));
    EXPECT_EQ(ra.t.size(), 3000);
  };
  expect_same_pca(plain_pca, one_pass, plain_pca, general);
  expect_same_pca(plain_pca, one_pass, padded_pca, one_pass);
  expect_same_array(plain_array, one_pass, plain_array, general);
  expect_same_array(plain_array, one_pass, padded_array, one_pass);
}

// The fast decimal path must give bit-identical results to std::from_chars wherever it answers.
TEST(ParseDecimalFast, AgreesBitForBitWithFromChars) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> mantissa(-1, 1);
  std::uniform_int_distribution<int> exponent(-30, 30), precision(1, 17);
  int fast = 0;
  char buf[64];
  for (int i = 0; i < 200000; ++i) {
    const double x = mantissa(rng) * std::pow(10.0, exponent(rng));
    const int prec = precision(rng);
    switch (i % 3) {
      case 0:
        std::snprintf(buf, sizeof buf, "%.*g", prec, x);
        break;
      case 1:
        std::snprintf(buf, sizeof buf, "%.*f", prec % 10, x);
        break;
      default:
        std::snprintf(buf, sizeof buf, "%.*e", prec, x);
        break;
    }
    const std::string_view text(buf);
    double expected = 0, got = 0;
    auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), expected);
    ASSERT_EQ(ec, std::errc()) << text;
    if (ParseDecimalFast(text, &got)) {
      ++fast;
      ASSERT_EQ(std::memcmp(&got, &expected, sizeof got), 0) << text;
    }
  }
  EXPECT_GT(fast, 100000);  // the common sensor formats take the fast path
  for (const char* odd : {"", "-", ".", "e5", "1e", "1e+", "--1", "1.2.3", "0x10", "nan", "inf",
                          "12345678901234567890", "1e23", "1e-23", "9007199254740993"}) {
    double v = 7;
    EXPECT_FALSE(ParseDecimalFast(odd, &v)) << odd;
    EXPECT_EQ(v, 7) << odd;
  }
  double v;
  ASSERT_TRUE(ParseDecimalFast("-0", &v));
  EXPECT_TRUE(std::signbit(v));
  ASSERT_TRUE(ParseDecimalFast("000123.4500", &v));
  EXPECT_EQ(v, 123.45);
}

TEST(Utf8, AcceptsWellFormedAndRejectsMalformedSequences) {
  EXPECT_TRUE(IsValidUtf8("plain ascii"));
  EXPECT_TRUE(IsValidUtf8("\xC2\xB5m \xE2\x80\x94 \xF0\x9F\x98\x80"));  // µm — 😀
  EXPECT_FALSE(IsValidUtf8("\xE2\x80"));                                // truncated
  EXPECT_FALSE(IsValidUtf8("\xED\xA0\x80"));                            // surrogate
  EXPECT_FALSE(IsValidUtf8("\xF4\x90\x80\x80"));                        // past U+10FFFF
  EXPECT_FALSE(IsValidUtf8("\x80"));                                    // lone continuation
}

TEST(RecordingParser, RejectsTooManyColumns) {
  RecordingLimits limits;
  limits.max_columns = 10;
  RecordingParser parser("wide.csv", false, limits);
  std::string header = "position";
  for (int i = 0; i < 20; ++i) header += ",s" + std::to_string(i);
  Status s = ParseAll(header + "\n", &parser);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.line(), 1);
  EXPECT_EQ(s.column(), 11);
}

TEST(RecordingParser, ValidatingParserKeepsNoNumbersButSummarises) {
  RecordingParser parser("v.csv", false);
  ASSERT_TRUE(ParseAll("position,s1\na,1\nb,2\na,3\n", &parser).ok());
  EXPECT_EQ(parser.summary().rows, 3);
  EXPECT_EQ(parser.summary().positions, 2);
  PcaRecording rec;
  EXPECT_EQ(parser.TakePca(&rec).code(), StatusCode::kInternal);
}

TEST(RecordingParser, AveragesRepeatedRowsOfOnePosition) {
  RecordingParser parser("v.csv", true);
  ASSERT_TRUE(ParseAll("position,s1\na,1\nb,2\na,3\n", &parser).ok());
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  EXPECT_DOUBLE_EQ(rec.readings(0, 0), 2.0);
  EXPECT_EQ(rec.rows_per_position, (std::vector<int64_t>{2, 1}));
}

TEST(RecordingParser, TakingTheWrongLayoutIsAClearError) {
  RecordingParser parser("v.csv", true);
  ASSERT_TRUE(ParseAll("position,s1\na,1\n", &parser).ok());
  ArrayRecording rec;
  Status s = parser.TakeArray(&rec);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("not an array recording"), std::string::npos);
}

}  // namespace
}  // namespace calibd::server
