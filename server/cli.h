// The command line of SPEC §1: serve, calibrate, simulate.
#ifndef CALIBD_SERVER_CLI_H_
#define CALIBD_SERVER_CLI_H_

namespace calibd::server {

// Exit codes of `calibd calibrate` (SPEC §1); also used for command-line errors.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;          // environment or internal error
inline constexpr int kExitBadInput = 2;         // bad input: file, line, column on stderr
inline constexpr int kExitNotDeterminable = 3;  // the data cannot determine the parameters
inline constexpr int kExitTimeLimit = 4;        // the time limit (--job-seconds) was reached

// Runs `calibd` with the process's arguments; returns the exit code.
int RunCli(int argc, char** argv);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_CLI_H_
