#include "carousel/studio/defaults.h"

#include <cstdlib>

namespace carousel::studio {

std::filesystem::path DefaultDataDir() {
  if (const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR"); env != nullptr && *env) {
    return env;
  }
  return CAROUSEL_DEFAULT_SHARED_DATA_DIR;
}

std::filesystem::path DefaultFirmwarePath() { return CAROUSEL_DEFAULT_FIRMWARE_ELF; }

}  // namespace carousel::studio
