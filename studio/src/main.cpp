// carousel: the command-line program. All logic lives in carousel_studio (cli.cpp).
#include <csignal>
#include <iostream>

#include "carousel/studio/cli.h"

int main(int argc, char** argv) {
  // Past a file-size limit (ulimit -f, a quota), writes fail with EFBIG and the program says
  // which file, instead of dying of SIGXFSZ halfway through a session.
  std::signal(SIGXFSZ, SIG_IGN);
  return carousel::studio::RunCli(argc, argv, std::cout, std::cerr);
}
