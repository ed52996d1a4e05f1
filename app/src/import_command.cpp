// carousel import SOURCE --out SESSION
#include <memory>

#include "carousel/studio/import.h"
#include "command.h"

namespace carousel::app {
namespace {

struct ImportArgs {
  studio::ImportOptions options;
  std::string format = "middlebury";
  std::string link = "copy";
  std::filesystem::path out;
};

}  // namespace

void AddImportCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<ImportArgs>();
  command
      .add_option("source", args->options.source,
                  "Middlebury *_par.txt, or a COLMAP sparse text model folder")
      ->required();
  command.add_option("--format", args->format, "middlebury or colmap")
      ->check(CLI::IsMember({"middlebury", "colmap"}))
      ->capture_default_str();
  command.add_option("--images", args->options.images_dir,
                     "folder of the photos (default: beside the par file)");
  command.add_option("--out", args->out, "session folder to create")->required();
  command.add_option("--link", args->link, "copy, hard or symbolic")
      ->check(CLI::IsMember({"copy", "hard", "symbolic"}))
      ->capture_default_str();
  command.add_option("--product", args->options.product, "product name");
  command.add_flag("--force", args->options.overwrite, "replace an existing session folder");
  command.add_option("--masks", args->options.masks_dir,
                     "folder of the dataset's own silhouettes, one per photo (<stem>.png, ...): "
                     "the reconstruction starts from them and checks them against the other "
                     "views");
  command.add_flag("--keep-frame", args->options.keep_frame,
                   "keep the dataset's world frame (default: stand it upright, +Z up along the "
                   "camera ring's axis, the origin on it where the cameras look)");
  dispatch.On(&command, [args](Io& io) {
    using Options = studio::ImportOptions;
    args->options.format =
        args->format == "colmap" ? Options::Format::kColmap : Options::Format::kMiddlebury;
    args->options.transfer = args->link == "hard"       ? Options::Transfer::kHardLink
                             : args->link == "symbolic" ? Options::Transfer::kSymlink
                                                        : Options::Transfer::kCopy;
    CreateParentFolder(args->out);
    CliProgress cli(io.err);
    const studio::ImportResult result =
        studio::ImportDataset(args->options, args->out, cli.progress());
    io.out << "session " << result.session.string() << ": " << result.views
           << " views imported; world frame " << result.frame << "\n";
    return kExitOk;
  });
}

}  // namespace carousel::app
