// carousel texture SESSION, carousel texture atlas MESH --out OBJ
#include <iomanip>
#include <memory>

#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/studio/texture_session.h"
#include "carousel/texture/atlas.h"
#include "command.h"
#include "print.h"

namespace carousel::app {
namespace {

struct TextureArgs {
  studio::TextureSessionOptions options;
  std::filesystem::path session;
};

struct AtlasArgs {
  texture::AtlasOptions options;
  std::filesystem::path mesh;
  std::filesystem::path out;
  std::filesystem::path charts_image;
};

int RunTextureAtlas(AtlasArgs& args, Io& io) {
  CreateParentFolder(args.out);
  CliProgress cli(io.err);
  Mesh mesh = ReadMesh(args.mesh, {.read_uvs = false});
  Stopwatch total;
  const texture::AtlasResult result = texture::BuildAtlas(&mesh, args.options, cli.progress());
  const double seconds = total.ElapsedSeconds() - result.seconds_quality;
  WriteMesh(mesh, args.out);
  const int size = result.size;
  if (!args.charts_image.empty()) {
    CreateParentFolder(args.charts_image);
    WriteImage(args.charts_image, texture::DrawCharts(mesh, std::min(size, 4096)));
  }
  const texture::AtlasQuality& q = result.quality;
  io.out << std::fixed << std::setprecision(3) << "atlas " << args.out.string() << ": "
         << mesh.n_faces() << " faces, " << q.charts << " charts (" << result.charts_split
         << " split to flatten validly), " << texture::PackingModeName(args.options.packing.mode)
         << " packing in " << size << "x" << size << "\n"
         << "stretch: L2 " << std::setprecision(4) << q.l2_stretch << " (worst face "
         << std::setprecision(2) << q.max_face_stretch << "), angle distortion "
         << q.angle_distortion_deg << " deg\n"
         << "utilization " << std::setprecision(1) << 100.0 * q.utilization << " %, "
         << std::setprecision(0) << q.texels_per_metre << " texels per metre\n"
         << std::setprecision(3) << "time " << seconds << " s: charts " << result.seconds_charts
         << " s, flattening " << result.seconds_parameterization << " s, packing "
         << result.seconds_packing << " s\n";
  if (!q.Valid()) {
    io.err << "carousel texture atlas: the atlas failed its checks (flipped " << q.flipped_faces
           << ", overlapping texels " << q.overlapping_texels << ", gutter " << q.gutter_violations
           << ")\n";
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace

void AddTextureCommands(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<TextureArgs>();
  command.require_subcommand(0, 1);
  command.add_option("session", args->session, "session folder (with recon/mesh.ply)");
  AddOptionFlags(&command, args->options, studio::TextureSessionOptions::Fields());
  dispatch.On(&command, [args](Io& io) {
    if (args->session.empty()) {
      io.err << "carousel texture: a session folder (or `atlas MESH --out OUT.obj`) is required\n";
      return static_cast<int>(kExitUsage);
    }
    CliProgress cli(io.err);
    const studio::TextureSessionResult result =
        studio::TextureSession(args->session, args->options, cli.progress());
    PrintTexture(args->session, result, io.out);
    return static_cast<int>(kExitOk);
  });

  auto atlas = std::make_shared<AtlasArgs>();
  CLI::App* atlas_command =
      command.add_subcommand("atlas", "charts, flattening and packing of a mesh: an OBJ with UVs");
  atlas_command->add_option("mesh", atlas->mesh, "mesh file (OBJ, PLY, OFF)")->required();
  atlas_command->add_option("--out", atlas->out, "output OBJ with UVs")->required();
  AddOptionFlags(atlas_command, atlas->options, texture::AtlasOptions::Fields());
  atlas_command->add_option("--charts-image", atlas->charts_image, "PNG of the charts");
  dispatch.On(atlas_command, [atlas](Io& io) { return RunTextureAtlas(*atlas, io); });
}

}  // namespace carousel::app
