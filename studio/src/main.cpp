// carousel: the command-line program. All logic lives in carousel_studio (cli.cpp).
#include <iostream>

#include "carousel/studio/cli.h"

int main(int argc, char** argv) {
  return carousel::studio::RunCli(argc, argv, std::cout, std::cerr);
}
