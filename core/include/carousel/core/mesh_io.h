// Mesh files (OBJ, PLY, OFF) read and written through OpenMesh, with the checks OpenMesh does
// not make: a missing, empty, truncated or garbage file, an index out of range, a face OpenMesh
// had to drop, or a non-finite coordinate is a FormatError naming the file and the reason.
// Writes are atomic (file_util.h). UVs are per halfedge, v up (OBJ convention).
#pragma once

#include <filesystem>

#include "carousel/core/mesh.h"

namespace carousel {

struct MeshReadOptions {
  // Read texture coordinates (OBJ `vt`) into the mesh's per-halfedge UVs when present.
  bool read_uvs = true;
};

// \throw IoError (missing, unreadable) or FormatError (empty, unsupported extension, garbage,
//        truncated, bad index, dropped faces, non-finite coordinates), naming the file.
Mesh ReadMesh(const std::filesystem::path& path, const MeshReadOptions& options = {});

struct MeshWriteOptions {
  bool binary = true;          // PLY only: binary little-endian (true) or ASCII
  bool write_uvs = true;       // OBJ only: write per-halfedge UVs when mesh.has_uvs()
  bool write_normals = false;  // write vertex normals
  int precision = 9;           // significant digits in text formats
  bool overwrite = true;       // see AtomicWriteOptions
};

// Writes by extension (.obj, .ply, .off). \throw InvalidArgument for an unknown extension or a
// mesh without faces; IoError when the file cannot be written (previous file untouched).
void WriteMesh(const Mesh& mesh, const std::filesystem::path& path,
               const MeshWriteOptions& options = {});

}  // namespace carousel
