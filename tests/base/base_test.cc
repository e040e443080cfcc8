// The base library (base/): UTF-8 validation and repair, URL encoding, SHA-256, Status, the job
// vocabulary.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <utility>

#include "base/job_state.h"
#include "base/sha256.h"
#include "base/status.h"
#include "base/url.h"
#include "base/utf8.h"

namespace calibd {
namespace {

TEST(Utf8, AcceptsValidTextOfEveryLength) {
  EXPECT_TRUE(IsValidUtf8(""));
  EXPECT_TRUE(IsValidUtf8("plain ascii"));
  EXPECT_TRUE(IsValidUtf8("\xC2\xB5m \xE2\x80\x94 \xF0\x9F\x98\x80"));  // µm — 😀
  EXPECT_TRUE(IsValidUtf8("\xF4\x8F\xBF\xBF"));                         // U+10FFFF
}

TEST(Utf8, RefusesTruncatedOverlongSurrogateAndOutOfRangeSequences) {
  EXPECT_FALSE(IsValidUtf8("\xE2\x80"));          // truncated at the end
  EXPECT_FALSE(IsValidUtf8("\xE2\x80x"));         // truncated before a letter
  EXPECT_FALSE(IsValidUtf8("\xC0\xAF"));          // overlong '/'
  EXPECT_FALSE(IsValidUtf8("\xE0\x80\xAF"));      // overlong, 3 bytes
  EXPECT_FALSE(IsValidUtf8("\xED\xA0\x80"));      // surrogate U+D800
  EXPECT_FALSE(IsValidUtf8("\xF4\x90\x80\x80"));  // past U+10FFFF
  EXPECT_FALSE(IsValidUtf8("\x80"));              // lone continuation byte
  EXPECT_FALSE(IsValidUtf8("\xFF"));
}

TEST(Utf8, SanitizeReplacesEachInvalidByteAndKeepsValidText) {
  EXPECT_EQ(SanitizeUtf8("a\xC2\xB5z"), "a\xC2\xB5z");
  EXPECT_EQ(SanitizeUtf8("a\xFF"
                         "b"),
            "a\xEF\xBF\xBD"
            "b");
  EXPECT_EQ(SanitizeUtf8("\xE2\x80"), "\xEF\xBF\xBD\xEF\xBF\xBD");
  EXPECT_TRUE(IsValidUtf8(SanitizeUtf8("\xC0\xAF\xED\xA0\x80 ok \xF4\x90\x80\x80")));
}

TEST(Url, EncodesAllButUnreservedCharactersInUpperCaseHex) {
  EXPECT_EQ(UrlEncode("SN-0001_a.b~c"), "SN-0001_a.b~c");
  EXPECT_EQ(UrlEncode("a b/c?d&e=f#"), "a%20b%2Fc%3Fd%26e%3Df%23");
  EXPECT_EQ(UrlEncode("\xC2\xB5"), "%C2%B5");
  EXPECT_EQ(UrlEncode(std::string("\0", 1)), "%00");
}

TEST(Sha256, MatchesTheFipsTestVectorsWholeAndInPieces) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  Sha256 sha;
  const std::string text = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
  for (size_t i = 0; i < text.size(); i += 5) sha.Update(std::string_view(text).substr(i, 5));
  EXPECT_EQ(sha.HexDigest(), "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  sha.Update("abc");  // reset after a digest: usable again
  EXPECT_EQ(sha.HexDigest(), Sha256Hex("abc"));
}

TEST(JobState, EveryValueHasTheSpecNameAndParsesBack) {
  const std::pair<JobStatus, const char*> statuses[] = {{JobStatus::kQueued, "queued"},
                                                        {JobStatus::kRunning, "running"},
                                                        {JobStatus::kSucceeded, "succeeded"},
                                                        {JobStatus::kFailed, "failed"}};
  for (const auto& [value, name] : statuses) {
    EXPECT_STREQ(Name(value), name);
    JobStatus parsed = value == JobStatus::kQueued ? JobStatus::kFailed : JobStatus::kQueued;
    ASSERT_TRUE(Parse(name, &parsed)) << name;
    EXPECT_EQ(parsed, value) << name;
  }
  const std::pair<ServeState, const char*> states[] = {{ServeState::kNone, ""},
                                                       {ServeState::kAccepted, "accepted"},
                                                       {ServeState::kRejected, "rejected"},
                                                       {ServeState::kRevoked, "revoked"}};
  for (const auto& [value, name] : states) {
    EXPECT_STREQ(Name(value), name);
    ServeState parsed = value == ServeState::kRevoked ? ServeState::kNone : ServeState::kRevoked;
    ASSERT_TRUE(Parse(name, &parsed)) << name;
    EXPECT_EQ(parsed, value) << name;
  }
  EXPECT_STREQ(Name(GateVerdict::kNone), "");
  EXPECT_STREQ(Name(GateVerdict::kAccepted), "accepted");
  EXPECT_STREQ(Name(GateVerdict::kRejected), "rejected");
  EXPECT_STREQ(Name(Decision::kNone), "");
  EXPECT_STREQ(Name(Decision::kRevoked), "revoked");
  EXPECT_STREQ(Name(Decision::kAccepted), "accepted");
  GateVerdict verdict = GateVerdict::kNone;
  ASSERT_TRUE(Parse("rejected", &verdict));
  EXPECT_EQ(verdict, GateVerdict::kRejected);
  Decision decision = Decision::kNone;
  ASSERT_TRUE(Parse("revoked", &decision));
  EXPECT_EQ(decision, Decision::kRevoked);
  std::ostringstream printed;  // what a failing EXPECT_EQ shows
  printed << JobStatus::kRunning << "/" << ServeState::kRevoked << "/" << GateVerdict::kRejected;
  EXPECT_EQ(printed.str(), "running/revoked/rejected");
}

TEST(JobState, UnknownTextIsRefusedAndLeavesTheValue) {
  JobStatus status = JobStatus::kRunning;
  for (const char* text : {"bogus", "", "Queued", "succeeded ", "revoked"}) {
    EXPECT_FALSE(Parse(text, &status)) << text;
    EXPECT_EQ(status, JobStatus::kRunning) << text;
  }
  ServeState state = ServeState::kRejected;
  EXPECT_FALSE(Parse("queued", &state));
  EXPECT_FALSE(Parse("Accepted", &state));
  EXPECT_EQ(state, ServeState::kRejected);
  GateVerdict verdict = GateVerdict::kAccepted;
  EXPECT_FALSE(Parse("revoked", &verdict));  // a person's decision, not the gate's verdict
  EXPECT_EQ(verdict, GateVerdict::kAccepted);
}

TEST(Status, CarriesCodeMessageAndLocation) {
  Status s = Status::InvalidInput("bad number");
  s.WithFile("r.csv").WithLocation(3, 7).WithField("g0_x");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(std::string(StatusCodeName(s.code())), "invalid_input");
  EXPECT_EQ(s.ToString(), "r.csv:3:7: field 'g0_x': bad number");
  EXPECT_EQ(s.field(), "g0_x");
  EXPECT_TRUE(Status::Ok().ok());
}

}  // namespace
}  // namespace calibd
