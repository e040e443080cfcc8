// A CSV text in the array layout (calibd's own, as the simulators write it) parsed into the
// columns the array methods take, as the server's recording parser reads an upload. Failures are
// test failures (EXPECT), the recording then empty.
#ifndef CALIBD_TESTS_LIB_ARRAY_CSV_H_
#define CALIBD_TESTS_LIB_ARRAY_CSV_H_

#include <gtest/gtest.h>

#include <string>

#include "formats/recording.h"

namespace calibd::testing {

inline server::ArrayRecording ArrayRecordingFromCsv(const std::string& csv) {
  server::RecordingParser parser("recording.csv", /*collect=*/true);
  const Status s = server::ParseRecording(csv, &parser);
  EXPECT_TRUE(s.ok()) << s.ToString();
  server::ArrayRecording rec;
  EXPECT_TRUE(parser.TakeArray(&rec).ok());
  return rec;
}

}  // namespace calibd::testing

#endif  // CALIBD_TESTS_LIB_ARRAY_CSV_H_
