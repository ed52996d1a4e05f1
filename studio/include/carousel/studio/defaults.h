// Where this build finds what it was configured with: the shared test data (models for the
// simulated rig) and the turntable firmware ELF (for the simulated controller in simavr).
#pragma once

#include <filesystem>

namespace carousel::studio {

// $CAROUSEL_SHARED_DATA_DIR, else the folder this build was configured with (../shared/data
// beside the checkout).
std::filesystem::path DefaultDataDir();

// The firmware's build location (set at configure time).
std::filesystem::path DefaultFirmwarePath();

}  // namespace carousel::studio
