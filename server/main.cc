// The calibd executable: a thin shell around the command line in server/cli.h.
#include "server/cli.h"

int main(int argc, char** argv) { return calibd::server::RunCli(argc, argv); }
