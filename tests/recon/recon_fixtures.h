// Simulated captures shared by the recon tests, rendered once per test binary.
#pragma once

#include <string>

#include "carousel/sim/sim_session.h"

namespace carousel::recon::testing {

// "shoe", "bottle" (the shared glTF models, 25 cm long), "ring" (a torus lying on the table:
// a concavity), "sphere" or "mug" (15 cm tall, its handle a see-through opening): 16 views of
// 960x640 (the models and the mug: 12 of 1296x864) with noise and JPEG, background plates,
// truth masks.
// "scene/material[/backdrop[/flags]]" overrides its materials (white: the exposure lowered so
// that it is not clipped; black; glossy: highlights; see-through), on the default light
// backdrop (black: on a black one) or on the one named (grey, black, white, light). Flags,
// joined by '+': "shadow" a contact shadow on the plate; "studio" what a real studio shows
// (the key light's soft cast shadow on the plate and the sweep, the backdrop light's falloff,
// lens vignetting) with 3 x 3 samples per pixel (no pixel is exactly half covered, so the
// truth has no ties); "backlit" a backlit mask shot beside every photo; "small" a product of
// 12 cm instead of 25 (framed as tightly: the plate then fills the frame's lower half and
// reaches its border).
const sim::SimViews& SimulatedCapture(const std::string& scene);

}  // namespace carousel::recon::testing
