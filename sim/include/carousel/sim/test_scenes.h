// Procedural scenes with known geometry, for checking the renderer and every later stage
// against ground truth. All in the turntable frame, metres.
#pragma once

#include "carousel/sim/scene.h"

namespace carousel::sim {

// A sphere (subdivided icosahedron, 20 * 4^subdivisions triangles) of uniform colour.
Scene MakeSphereScene(double radius, const Eigen::Vector3d& centre, int subdivisions = 5,
                      const Eigen::Vector3f& color = {0.8f, 0.3f, 0.2f});

// A square plate in the z = `height` plane, centred on the axis, `size` metres wide, with a
// black-and-white checkerboard texture of `squares` x `squares` squares, `texels_per_square`
// texels each. The inner checker corners sit at (-size/2 + i*size/squares, ...).
Scene MakeCheckerPlaneScene(double size, int squares, double height = 0.0,
                            int texels_per_square = 64);

}  // namespace carousel::sim
