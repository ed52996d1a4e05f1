// Procedural meshes with known geometry: test fixtures, self-check, synthetic scenes.
// All are triangle meshes in metres, counter-clockwise outward (closed ones) or facing +Z
// (the disc), with normals computed.
#pragma once

#include <cstdint>

#include "carousel/core/mesh.h"

namespace carousel {

// Icosahedron subdivided `subdivisions` times (20 * 4^s faces), vertices on the sphere.
// \throw InvalidArgument if radius <= 0 or subdivisions outside 0..8.
Mesh MakeIcosphere(double radius, int subdivisions, const OpenMesh::Vec3d& centre = {0, 0, 0});

// Torus about +Z: `major_radius` to the tube centre, `minor_radius` of the tube;
// 2 * major_segments * minor_segments faces. \throw InvalidArgument on bad sizes/counts.
Mesh MakeTorus(double major_radius, double minor_radius, int major_segments, int minor_segments);

// Closed cylinder about +Z from z = 0 to z = height, with capped ends (fans around a centre
// vertex); 2 * segments * rings + 2 * segments faces. \throw InvalidArgument.
Mesh MakeCylinder(double radius, double height, int segments, int rings);

// Open disc in the z = 0 plane facing +Z, `rings` concentric rings of `segments` (one boundary
// loop). \throw InvalidArgument.
Mesh MakeDisc(double radius, int segments, int rings);

// A lumpy closed blob (a sum of Gaussian lobes, about 1.6 m across) contoured by marching
// tetrahedra on a resolution^3 grid: the kind of mesh a reconstruction produces, with
// irregular triangles and slivers where the surface passes close to grid corners. `noise` adds
// random bumps to the field (up to about that many cells; seeded, deterministic), which can
// also leave small bubbles. About 15 * resolution^2 faces. \throw InvalidArgument (resolution
// outside 4..512, noise < 0).
Mesh MakeMarchingBlob(int resolution, double noise = 0.1, std::uint64_t seed = 1);
// The same family with its shape drawn from `seed` too: a central lobe and 3 to 7 more of
// random size and weight reaching out in random directions (for measuring on surfaces nothing
// was tuned on). \throw InvalidArgument as MakeMarchingBlob.
Mesh MakeRandomBlob(int resolution, double noise, std::uint64_t seed);

}  // namespace carousel
