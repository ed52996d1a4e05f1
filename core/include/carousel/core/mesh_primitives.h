// Procedural meshes with known geometry: test fixtures, self-check, synthetic scenes.
// All are triangle meshes in metres, counter-clockwise outward (closed ones) or facing +Z
// (the disc), with normals computed.
#pragma once

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

}  // namespace carousel
