// Marching tetrahedra over one grid cube: the contouring step shared by the visual hull
// (recon) and the procedural marching-cubes blob (mesh_primitives).
//
// Cube corners: bit 0 = +x, bit 1 = +y, bit 2 = +z. The cube is split into the six
// Freudenthal tetrahedra around the main diagonal 0-7; every cube of a grid split the same
// way, neighbouring cubes agree on their shared faces, and the surface is watertight and
// manifold with no ambiguous case (unlike marching cubes). Inside: value > 0.
#pragma once

#include <array>

namespace carousel {

// Calls emit(edges, towards_outside) for every triangle of the zero set in the cube, where
// edges[k] = {a, b} are the corners (a < b) of the cube edge carrying the triangle's k-th
// vertex, and towards_outside points from the tetrahedron's inside corners to its outside
// ones (to orient the triangle). `Vec` is any 3-vector type with +, - and / by a scalar.
template <typename Vec, typename Emit>
void MarchCube(const std::array<double, 8>& value, const std::array<Vec, 8>& position,
               Emit&& emit) {
  constexpr std::array<std::array<int, 4>, 6> kTetrahedra = {
      {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}}};
  auto edge = [](int a, int b) {
    return a < b ? std::array<int, 2>{a, b} : std::array<int, 2>{b, a};
  };
  for (const auto& tet : kTetrahedra) {
    std::array<int, 4> in{}, out{};
    int n_in = 0;
    int n_out = 0;
    Vec centre_in = position[tet[0]] - position[tet[0]];
    Vec centre_out = centre_in;
    for (const int corner : tet) {
      if (value[corner] > 0.0) {
        in[n_in++] = corner;
        centre_in = centre_in + position[corner];
      } else {
        out[n_out++] = corner;
        centre_out = centre_out + position[corner];
      }
    }
    if (n_in == 0 || n_out == 0) continue;
    const Vec towards_outside = centre_out / n_out - centre_in / n_in;
    if (n_in == 1 || n_out == 1) {
      const int apex = n_in == 1 ? in[0] : out[0];
      const auto& others = n_in == 1 ? out : in;
      emit(std::array<std::array<int, 2>, 3>{edge(apex, others[0]), edge(apex, others[1]),
                                             edge(apex, others[2])},
           towards_outside);
    } else {
      emit(std::array<std::array<int, 2>, 3>{edge(in[0], out[0]), edge(in[0], out[1]),
                                             edge(in[1], out[1])},
           towards_outside);
      emit(std::array<std::array<int, 2>, 3>{edge(in[0], out[0]), edge(in[1], out[1]),
                                             edge(in[1], out[0])},
           towards_outside);
    }
  }
}

}  // namespace carousel
