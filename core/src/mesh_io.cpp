#include "carousel/core/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <sstream>
#include <string_view>

#include <OpenMesh/Core/IO/MeshIO.hh>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/logging.h"
#include "carousel/core/text.h"
#include "openmesh_streams.h"

namespace carousel {
namespace {

enum class MeshFormat { kObj, kPly, kOff };

MeshFormat FormatFromExtension(const std::filesystem::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (extension == ".obj") return MeshFormat::kObj;
  if (extension == ".ply") return MeshFormat::kPly;
  if (extension == ".off") return MeshFormat::kOff;
  throw FormatError(path,
                    "unsupported mesh format '" + extension + "' (expected .obj, .ply or .off)");
}

// What a file declares, found by our own scan before OpenMesh parses it.
struct Expected {
  std::size_t vertices = 0;
  std::size_t triangles = 0;  // faces after fan triangulation, when known exactly
  bool triangles_exact = false;
  std::size_t declared_faces = 0;  // faces as declared (polygons)
  bool has_texcoords = false;
};

// Rejects bytes that never occur in a text mesh (NUL, most control characters).
void RequireText(const std::filesystem::path& path, std::string_view text, const char* kind) {
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == 0 || (c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f') || c == 0x7f) {
      throw FormatError(path, std::string("not a text ") + kind + " file: binary data at byte " +
                                  std::to_string(i));
    }
  }
}

// A text mesh written by any real tool ends with a line end; a file cut short by a crash or a
// failed copy almost always ends inside a line, which could otherwise still parse (a face
// "f 12 13 1" cut from "f 12 13 14").
void RequireCompleteLastLine(const std::filesystem::path& path, std::string_view text) {
  std::size_t end = text.size();
  while (end > 0 && (text[end - 1] == ' ' || text[end - 1] == '\t')) --end;
  if (end == 0 || text[end - 1] == '\n' || text[end - 1] == '\r') return;
  const std::size_t start = text.rfind('\n', end - 1);
  std::string last(text.substr(start == std::string_view::npos ? 0 : start + 1));
  if (last.size() > 40) last = last.substr(0, 40) + "...";
  throw FormatError(path, "truncated: the file ends inside a line ('" + last + "')");
}

bool ParseDouble(std::string_view token, double* value) {
  const std::string copy(token);  // strtod needs a terminated string
  char* end = nullptr;
  *value = std::strtod(copy.c_str(), &end);
  return end == copy.c_str() + copy.size() && !copy.empty();
}

bool ParseLong(std::string_view token, long* value) {
  const auto result = std::from_chars(token.data(), token.data() + token.size(), *value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

// Resolves an OBJ index (1-based, or negative = relative to the end) against `count` elements.
bool ResolveObjIndex(long index, std::size_t count, std::size_t* resolved) {
  if (index > 0 && static_cast<std::size_t>(index) <= count) {
    *resolved = static_cast<std::size_t>(index - 1);
    return true;
  }
  if (index < 0 && static_cast<std::size_t>(-index) <= count) {
    *resolved = count - static_cast<std::size_t>(-index);
    return true;
  }
  return false;
}

Expected ScanObj(const std::filesystem::path& path, std::string_view text) {
  RequireText(path, text, "OBJ");
  RequireCompleteLastLine(path, text);
  Expected expected;
  expected.triangles_exact = true;
  std::size_t texcoords = 0;
  std::size_t line_number = 0;
  std::size_t position = 0;
  while (position < text.size()) {
    std::size_t end = text.find('\n', position);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(position, end - position);
    position = end + 1;
    ++line_number;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    const std::vector<std::string_view> tokens = SplitWhitespace(line);
    if (tokens.empty()) continue;
    const std::string where = "line " + std::to_string(line_number) + ": ";
    if (tokens[0] == "v") {
      if (tokens.size() < 4) throw FormatError(path, where + "vertex needs 3 coordinates");
      for (int k = 1; k <= 3; ++k) {
        double value = 0.0;
        if (!ParseDouble(tokens[k], &value)) {
          throw FormatError(
              path, where + "vertex coordinate '" + std::string(tokens[k]) + "' is not a number");
        }
        if (!std::isfinite(value)) {
          throw FormatError(path, where + "vertex coordinate is not finite");
        }
      }
      ++expected.vertices;
    } else if (tokens[0] == "vt") {
      if (tokens.size() < 3) throw FormatError(path, where + "texture coordinate needs u and v");
      ++texcoords;
    } else if (tokens[0] == "f") {
      if (tokens.size() < 4) {
        throw FormatError(path, where + "face needs at least 3 vertices, has " +
                                    std::to_string(tokens.size() - 1));
      }
      for (std::size_t k = 1; k < tokens.size(); ++k) {
        const std::string_view ref = tokens[k];
        const std::size_t slash = ref.find('/');
        long index = 0;
        if (!ParseLong(ref.substr(0, slash), &index)) {
          throw FormatError(path, where + "bad face vertex reference '" + std::string(ref) + "'");
        }
        std::size_t resolved = 0;
        if (!ResolveObjIndex(index, expected.vertices, &resolved)) {
          throw FormatError(path, where + "face refers to vertex " + std::to_string(index) +
                                      " but " + std::to_string(expected.vertices) +
                                      " vertices are defined");
        }
        if (slash != std::string_view::npos) {
          const std::string_view rest = ref.substr(slash + 1);
          const std::string_view vt = rest.substr(0, rest.find('/'));
          if (!vt.empty()) {
            long vt_index = 0;
            if (!ParseLong(vt, &vt_index) || !ResolveObjIndex(vt_index, texcoords, &resolved)) {
              throw FormatError(path, where + "face refers to texture coordinate '" +
                                          std::string(vt) + "' but " + std::to_string(texcoords) +
                                          " are defined");
            }
            expected.has_texcoords = true;
          }
        }
      }
      ++expected.declared_faces;
      expected.triangles += tokens.size() - 3;
    }
  }
  if (expected.vertices == 0) throw FormatError(path, "no vertices");
  if (expected.declared_faces == 0) throw FormatError(path, "no faces");
  return expected;
}

int PlyScalarSize(std::string_view type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "int32" || type == "uint32" || type == "float" ||
      type == "float32") {
    return 4;
  }
  if (type == "double" || type == "float64") return 8;
  return 0;
}

Expected ScanPly(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  const std::string_view data(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (data.substr(0, 3) != "ply" || data.size() < 4 || (data[3] != '\n' && data[3] != '\r')) {
    throw FormatError(path, "not a PLY file: it does not start with 'ply'");
  }
  const std::size_t header_end = data.find("end_header");
  if (header_end == std::string_view::npos) {
    throw FormatError(path, "PLY header never ends (no end_header): truncated or not a PLY file");
  }
  std::size_t body = data.find('\n', header_end);
  if (body == std::string_view::npos) throw FormatError(path, "truncated after end_header");
  ++body;
  const std::string_view header = data.substr(0, header_end);
  RequireText(path, header, "PLY header of a");

  struct Element {
    std::string name;
    std::size_t count = 0;
    std::size_t min_bytes = 0;  // per element, binary
  };
  std::vector<Element> elements;
  std::string format;
  std::istringstream lines{std::string(header)};
  std::string line;
  while (std::getline(lines, line)) {
    const std::vector<std::string_view> tokens = SplitWhitespace(line);
    if (tokens.empty()) continue;
    if (tokens[0] == "format" && tokens.size() >= 2) {
      format = std::string(tokens[1]);
    } else if (tokens[0] == "element" && tokens.size() >= 3) {
      long count = 0;
      if (!ParseLong(tokens[2], &count) || count < 0) {
        throw FormatError(path, "PLY header: bad element count in '" + line + "'");
      }
      elements.push_back({std::string(tokens[1]), static_cast<std::size_t>(count), 0});
    } else if (tokens[0] == "property" && !elements.empty()) {
      if (tokens.size() >= 5 && tokens[1] == "list") {
        // A list holds at least its count; a face list at least 3 indices.
        const int count_size = PlyScalarSize(tokens[2]);
        const int item_size = PlyScalarSize(tokens[3]);
        if (!count_size || !item_size) {
          throw FormatError(path, "PLY header: unknown type in '" + line + "'");
        }
        elements.back().min_bytes +=
            count_size + (elements.back().name == "face" ? 3 * item_size : 0);
      } else if (tokens.size() >= 3) {
        const int size = PlyScalarSize(tokens[1]);
        if (!size) throw FormatError(path, "PLY header: unknown type in '" + line + "'");
        elements.back().min_bytes += size;
      }
    }
  }
  if (format.empty()) throw FormatError(path, "PLY header has no format line");
  Expected expected;
  for (const Element& element : elements) {
    if (element.name == "vertex") expected.vertices = element.count;
    if (element.name == "face") expected.declared_faces = element.count;
  }
  if (expected.vertices == 0) throw FormatError(path, "no vertices");
  if (expected.declared_faces == 0) throw FormatError(path, "no faces");
  expected.triangles = expected.declared_faces;  // at least
  const std::size_t body_size = data.size() - body;
  if (format == "ascii") {
    RequireText(path, data.substr(body), "PLY");
    RequireCompleteLastLine(path, data.substr(body));
    std::size_t rows = 0;
    bool in_row = false;
    for (std::size_t i = body; i < data.size(); ++i) {
      if (data[i] == '\n') {
        in_row = false;
      } else if (!std::isspace(static_cast<unsigned char>(data[i])) && !in_row) {
        in_row = true;
        ++rows;
      }
    }
    std::size_t declared_rows = 0;
    for (const Element& element : elements) declared_rows += element.count;
    if (rows < declared_rows) {
      throw FormatError(path, "truncated: the header declares " + std::to_string(declared_rows) +
                                  " rows of data, the file holds " + std::to_string(rows));
    }
  } else if (format == "binary_little_endian" || format == "binary_big_endian") {
    std::size_t min_body = 0;
    for (const Element& element : elements) min_body += element.count * element.min_bytes;
    if (body_size < min_body) {
      throw FormatError(path, "truncated: the header declares " +
                                  std::to_string(expected.vertices) + " vertices and " +
                                  std::to_string(expected.declared_faces) +
                                  " faces, needing at least " + std::to_string(min_body) +
                                  " bytes of data, the file holds " + std::to_string(body_size));
    }
  } else {
    throw FormatError(path, "PLY header: unknown format '" + format + "'");
  }
  return expected;
}

Expected ScanOff(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  const std::string_view data(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const std::size_t first_line_end = std::min(data.find('\n'), data.size());
  const std::vector<std::string_view> first = SplitWhitespace(data.substr(0, first_line_end));
  if (first.empty() || first[0].size() < 3 || first[0].substr(first[0].size() - 3) != "OFF") {
    throw FormatError(path, "not an OFF file: it does not start with 'OFF'");
  }
  if (first.size() >= 2 && first[1] == "BINARY") return Expected{};  // counts checked later
  RequireText(path, data, "OFF");
  RequireCompleteLastLine(path, data);
  // Counts may follow on the first line or on the next non-comment line.
  std::vector<std::string_view> tokens;
  std::size_t position = 0;
  std::size_t row = 0;
  std::size_t data_rows = 0;
  long counts[2] = {-1, -1};
  std::size_t counts_found = 0;
  while (position < data.size()) {
    std::size_t end = data.find('\n', position);
    if (end == std::string_view::npos) end = data.size();
    std::string_view line = data.substr(position, end - position);
    position = end + 1;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }
    std::vector<std::string_view> words = SplitWhitespace(line);
    if (row++ == 0) words.erase(words.begin());  // the OFF keyword
    if (words.empty()) continue;
    if (counts_found < 2) {
      for (std::string_view word : words) {
        if (counts_found < 2 && !ParseLong(word, &counts[counts_found++])) {
          throw FormatError(path, "OFF header: bad count '" + std::string(word) + "'");
        }
      }
      continue;
    }
    ++data_rows;
  }
  if (counts_found < 2 || counts[0] < 0 || counts[1] < 0) {
    throw FormatError(path, "OFF header has no vertex and face counts");
  }
  Expected expected;
  expected.vertices = static_cast<std::size_t>(counts[0]);
  expected.declared_faces = static_cast<std::size_t>(counts[1]);
  expected.triangles = expected.declared_faces;
  if (expected.vertices == 0) throw FormatError(path, "no vertices");
  if (expected.declared_faces == 0) throw FormatError(path, "no faces");
  if (data_rows < expected.vertices + expected.declared_faces) {
    throw FormatError(path, "truncated: the header declares " + std::to_string(expected.vertices) +
                                " vertices and " + std::to_string(expected.declared_faces) +
                                " faces, the file holds " + std::to_string(data_rows) + " rows");
  }
  return expected;
}

}  // namespace

Mesh ReadMesh(const std::filesystem::path& path, const MeshReadOptions& options) {
  const MeshFormat format = FormatFromExtension(path);
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  if (bytes.empty()) throw FormatError(path, "file is empty");
  Expected expected;
  switch (format) {
    case MeshFormat::kObj:
      expected = ScanObj(
          path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
      break;
    case MeshFormat::kPly:
      expected = ScanPly(path, bytes);
      break;
    case MeshFormat::kOff:
      expected = ScanOff(path, bytes);
      break;
  }

  Mesh mesh;
  OpenMesh::IO::Options io_options;
  if (options.read_uvs && format == MeshFormat::kObj && expected.has_texcoords) {
    io_options += OpenMesh::IO::Options::FaceTexCoord;
  }
  std::string openmesh_messages;
  bool ok = false;
  {
    internal::OpenMeshCapture capture;
    ok = OpenMesh::IO::read_mesh(mesh, path.string(), io_options);
    openmesh_messages = capture.Text();
  }
  if (!ok) {
    throw FormatError(path, "OpenMesh could not parse it" +
                                (openmesh_messages.empty() ? "" : ": " + openmesh_messages));
  }
  if (mesh.n_faces() == 0) throw FormatError(path, "no faces");
  if (mesh.n_vertices() < expected.vertices) {
    throw FormatError(path, "truncated: declares " + std::to_string(expected.vertices) +
                                " vertices, " + std::to_string(mesh.n_vertices()) + " were read");
  }
  for (Mesh::VertexHandle vertex : mesh.vertices()) {
    const OpenMesh::Vec3d& p = mesh.point(vertex);
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      throw FormatError(path,
                        "vertex " + std::to_string(vertex.idx()) + " has a non-finite coordinate");
    }
  }
  // Faces OpenMesh refused (repeated vertices) carry no area; faces it could only add by
  // duplicating vertices are non-manifold. Both are reported, never dropped in silence.
  if (expected.triangles_exact && mesh.n_faces() < expected.triangles) {
    CAROUSEL_LOG_WARN(path.string()
                      << ": " << expected.triangles - mesh.n_faces() << " of " << expected.triangles
                      << " triangles dropped (repeated vertex indices)");
  } else if (!expected.triangles_exact && mesh.n_faces() < expected.declared_faces) {
    CAROUSEL_LOG_WARN(path.string()
                      << ": " << expected.declared_faces - mesh.n_faces() << " of "
                      << expected.declared_faces << " faces dropped (repeated vertex indices)");
  }
  std::size_t nonmanifold = 0;
  for (Mesh::FaceHandle face : mesh.faces()) {
    if (mesh.status(face).fixed_nonmanifold()) ++nonmanifold;
  }
  if (nonmanifold > 0) {
    CAROUSEL_LOG_WARN(path.string() << ": " << nonmanifold
                                    << " faces are non-manifold and were given their own "
                                       "vertices");
  }
  mesh.set_has_uvs(io_options.check(OpenMesh::IO::Options::FaceTexCoord));
  mesh.RecomputeNormals();
  return mesh;
}

void WriteMesh(const Mesh& mesh, const std::filesystem::path& path,
               const MeshWriteOptions& options) {
  MeshFormat format;
  try {
    format = FormatFromExtension(path);
  } catch (const FormatError&) {
    throw InvalidArgument("WriteMesh: unsupported extension '" + path.extension().string() +
                          "' for " + path.string() + " (use .obj, .ply or .off)");
  }
  CAROUSEL_THROW_IF(mesh.n_faces() == 0, InvalidArgument,
                    "WriteMesh: the mesh for " << path.string() << " has no faces");
  std::error_code ec;
  const std::filesystem::path folder = path.parent_path();
  if (!folder.empty() && !std::filesystem::is_directory(folder, ec)) {
    throw IoError(path, "folder " + folder.string() + " does not exist");
  }
  if (!options.overwrite && std::filesystem::exists(path, ec)) {
    throw IoError(path, "file exists and would be overwritten");
  }
  OpenMesh::IO::Options io_options;
  if (format == MeshFormat::kPly && options.binary) io_options += OpenMesh::IO::Options::Binary;
  if (format == MeshFormat::kObj && options.write_uvs && mesh.has_uvs()) {
    io_options += OpenMesh::IO::Options::FaceTexCoord;
  }
  if (options.write_normals) io_options += OpenMesh::IO::Options::VertexNormal;
  if (format != MeshFormat::kObj) {
    // PLY and OFF are serialised in memory and written by WriteFileAtomic, which checks every
    // write: OpenMesh's own file output ignores a short write (a full disk, a size limit).
    std::ostringstream stream(std::ios::out | std::ios::binary);
    bool ok = false;
    std::string openmesh_messages;
    {
      internal::OpenMeshCapture capture;
      ok = OpenMesh::IO::write_mesh(mesh, stream, path.extension().string(), io_options,
                                    options.precision);
      openmesh_messages = capture.Text();
    }
    if (!ok) {
      throw IoError(
          path, "cannot write mesh" + (openmesh_messages.empty() ? "" : ": " + openmesh_messages));
    }
    const std::string bytes = stream.str();
    WriteFileAtomic(path,
                    std::span<const std::uint8_t>(
                        reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()),
                    {.overwrite = options.overwrite});
    return;
  }
  // Write beside the target under a temporary name with the same extension, then rename.
  std::filesystem::path temporary = TemporarySibling(path);
  temporary += path.extension();
  std::string openmesh_messages;
  bool ok = false;
  {
    internal::OpenMeshCapture capture;
    ok = OpenMesh::IO::write_mesh(mesh, temporary.string(), io_options, options.precision);
    openmesh_messages = capture.Text();
  }
  if (!ok) {
    std::filesystem::remove(temporary, ec);
    throw IoError(
        path, "cannot write mesh" + (openmesh_messages.empty() ? "" : ": " + openmesh_messages));
  }
  // A full disk can leave OpenMesh's stream short without an error: re-check the size.
  if (std::filesystem::file_size(temporary, ec) == 0 || ec) {
    std::filesystem::remove(temporary, ec);
    throw IoError(path, "cannot write mesh: nothing was written (disk full?)");
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    const int error = errno;
    std::filesystem::remove(temporary, ec);
    throw IoError(path, std::string("cannot move file into place: ") + std::strerror(error));
  }
  SyncFolder(folder);
}

}  // namespace carousel
