// Simulated captures shared by the recon tests, rendered once per test binary.
#pragma once

#include <string>

#include "carousel/sim/sim_session.h"

namespace carousel::recon::testing {

// "shoe", "bottle" (the shared glTF models, 25 cm long), "ring" (a torus lying on the table:
// a concavity) or "sphere": 16 views of 960x640 (the models: 12 of 1296x864) with noise
// and JPEG, background plates, truth masks.
// "scene/material[/backdrop]" overrides its materials (white: the exposure lowered so that it
// is not clipped; black; glossy: highlights), on the default light backdrop (black: on a black
// one) or on the one named (grey, black, light); ".../shadow" adds a contact shadow on the plate.
const sim::SimViews& SimulatedCapture(const std::string& scene);

}  // namespace carousel::recon::testing
