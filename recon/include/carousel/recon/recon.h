// recon: shape from silhouette. This header includes the stages (and the registration of a
// second pass).
//
// Input: std::vector<View> (photo + camera), never a calibration file. Stages, each
// `Result Stage(const Inputs&, const Options&, Progress&)`:
//   Silhouettes   alpha mask per photo (backdrop keying, background-plate differencing,
//                 boundary refinement, turntable plate removal) -> masks/ as 8-bit PNG
//   VisualHull    octree carving with mask distance transforms, marching cubes at sub-voxel
//                 accuracy, largest watertight component; outside an image = unknown
//   OptimizeMesh  Taubin smoothing, isotropic remeshing, quadric decimation to a face count
//                 (default 4,500); closed, manifold, outward-oriented Mesh
// and MeasureSilhouetteAgreement (reprojection.h): a mesh against the masks, in pixels.
// recon never includes calib or texture.
#pragma once

#include "carousel/recon/mesh_optimization.h"
#include "carousel/recon/registration.h"
#include "carousel/recon/reprojection.h"
#include "carousel/recon/silhouette.h"
#include "carousel/recon/visual_hull.h"
