// Procedural scenes with known geometry, for checking the renderer and every later stage
// against ground truth. All in the turntable frame, metres.
#pragma once

#include <opencv2/core.hpp>

#include "carousel/core/rigid3.h"

#include <string>

#include "carousel/core/mesh.h"
#include "carousel/sim/scene.h"

namespace carousel::sim {

// A mesh as a scene of one uniform colour (normals from the mesh), e.g. a procedural shape.
Scene SceneFromMesh(const Mesh& mesh, const Eigen::Vector3f& color, const std::string& source);

// A sphere (subdivided icosahedron, 20 * 4^subdivisions triangles) of uniform colour.
Scene MakeSphereScene(double radius, const Eigen::Vector3d& centre, int subdivisions = 5,
                      const Eigen::Vector3f& color = {0.8f, 0.3f, 0.2f});

// A torus lying on the table (about +Z, resting on z = 0): a shape with a concavity the
// silhouettes cannot see into (the hole, seen from low elevations, and the saddle inside).
Scene MakeRingScene(double major_radius, double minor_radius,
                    const Eigen::Vector3f& color = {0.2f, 0.45f, 0.75f});

// A mug standing on the table: a closed cylinder `height` tall (radius 0.4 x height) with a
// round handle on its side (+X at table angle 0) whose opening is see-through from the sides:
// a silhouette must keep that hole open.
Scene MakeMugScene(double height, const Eigen::Vector3f& color = {0.85f, 0.35f, 0.2f});

// A square plate in the z = `height` plane, centred on the axis, `size` metres wide, with a
// black-and-white checkerboard texture of `squares` x `squares` squares, `texels_per_square`
// texels each. The inner checker corners sit at (-size/2 + i*size/squares, ...).
Scene MakeCheckerPlaneScene(double size, int squares, double height = 0.0,
                            int texels_per_square = 64);

// A printed card: `image` (8-bit grey or BGR) printed on the front of a flat card of
// `thickness_m` whose back is plain grey, e.g. a calibration board on the turntable.
// `plane_from_pixel` maps image positions (OpenCV pixel convention) to the card's plane
// coordinates (x, y; z = 0, metres); `table_from_plane` places the plane on the table. The
// printed side faces the viewer who sees the image the right way round.
// Where a card (an image mapped to its plane by `plane_from_pixel`) stands on the turntable:
// centred on the axis, its image upright (image x along +X, image y down the card), the
// print facing the cameras at table angle 0 (towards -Y), leaning back `lean_deg` from
// vertical, its lowest edge `lift_m` above the plate. Returns table_from_plane.
Rigid3d StandCardOnTable(const Eigen::Matrix<double, 2, 3>& plane_from_pixel, const cv::Size& image,
                         double lean_deg, double lift_m);

Scene MakePrintedCardScene(const cv::Mat& image,
                           const Eigen::Matrix<double, 2, 3>& plane_from_pixel,
                           const Rigid3d& table_from_plane, double thickness_m = 0.003);

}  // namespace carousel::sim
