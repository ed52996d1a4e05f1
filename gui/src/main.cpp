// carousel-studio: the photographer's window and the operator's one button.
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "carousel/core/error.h"
#include "carousel/core/version.h"
#include "studio_app.h"

int main(int argc, char** argv) {
  using namespace carousel;
  gui::StudioArgs args;
  try {
    args = gui::ParseStudioArgs(std::vector<std::string>(argv + 1, argv + argc));
  } catch (const Error& e) {
    std::cerr << "carousel-studio: " << e.what() << "\n";
    return 64;
  }
  if (args.help) {
    std::cout << gui::StudioUsage();
    return 0;
  }
  if (args.version) {
    std::cout << "carousel-studio " << kVersion << "\n";
    return 0;
  }
  try {
    gui::StudioApp app(std::move(args));
    return app.Run();
  } catch (const std::exception& e) {
    std::cerr << "carousel-studio: " << e.what() << "\n";
    return 1;
  }
}
