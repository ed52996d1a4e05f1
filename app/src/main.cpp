// carousel: the command-line program (app/src/cli.cpp holds its table of commands).
#include <csignal>
#include <iostream>

#include "carousel/app/cli.h"

int main(int argc, char** argv) {
  // Past a file-size limit (ulimit -f, a quota), writes fail with EFBIG and the program says
  // which file, instead of dying of SIGXFSZ halfway through a session.
  std::signal(SIGXFSZ, SIG_IGN);
  return carousel::app::RunCli(argc, argv, std::cout, std::cerr);
}
