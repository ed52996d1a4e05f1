// carousel reconstruct SESSION, carousel process SESSION...: the processing stages.
#include <memory>

#include "carousel/studio/pipeline.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/run_session.h"
#include "command.h"
#include "print.h"

namespace carousel::app {
namespace {

struct ReconstructArgs {
  studio::ReconstructOptions options;
  std::filesystem::path session;
};

struct PublishArgs {
  const CLI::App* command = nullptr;  // which publish flags were typed (WithGivenFlags)
  std::vector<std::filesystem::path> sessions;
  studio::PublishSessionOptions options;
  std::filesystem::path site;  // --out: the static catalog
  std::string site_title = "Catalog";
};

struct ProcessArgs {
  const CLI::App* command = nullptr;  // which publish flags were typed (WithGivenFlags)
  std::vector<std::filesystem::path> sessions;
  studio::ProcessOptions options;
};

// The texture flags of `carousel process`.
const OptionTable<studio::TextureSessionOptions>& ProcessTextureFields() {
  static const OptionTable<studio::TextureSessionOptions> table =
      studio::TextureSessionOptions::Fields().Only({"exclude-views"});
  return table;
}

// Every session in turn; a failing one is reported and the batch goes on. The exit code is
// the first failure's (0 when every session is processed).
int RunProcess(const ProcessArgs& args, Io& io) {
  int status = kExitOk;
  int failed = 0;
  for (const std::filesystem::path& session : args.sessions) {
    io.out << "session " << session.string() << "\n";
    try {
      CliProgress cli(io.err);
      // What the session was processed with before, changed where a flag says so.
      studio::ProcessOptions options = args.options;
      studio::TextureSessionOptions recorded_texture = args.options.texture;
      recorded_texture.grouping.exclude_views = studio::RecordedExcludedViews(session);
      options.texture = WithGivenFlags(*args.command, ProcessTextureFields(), args.options.texture,
                                       recorded_texture);
      options.publish =
          WithGivenFlags(*args.command, studio::PublishSessionOptions::Fields(),
                         args.options.publish, studio::RecordedPublishOptions(session));
      const studio::ProcessResult result = studio::ProcessSession(session, options, cli.progress());
      if (result.reconstruct) {
        io.out << "reconstruct: ran (" << result.reconstruct_reason << ")\n";
        PrintReconstruct(session, *result.reconstruct, io.out);
      } else {
        io.out << "reconstruct: current, skipped\n";
      }
      if (result.texture) {
        io.out << "texture: ran (" << result.texture_reason << ")\n";
        PrintTexture(session, *result.texture, io.out);
      } else {
        io.out << "texture: current, skipped\n";
      }
      if (result.publish) {
        PrintPublish(session, *result.publish, io.out);
      } else if (result.publish_reason == "current") {
        io.out << "publish: current, skipped\n";
      }
    } catch (const std::exception& e) {
      io.err << "carousel process: " << session.string() << ": error: " << e.what() << '\n';
      if (status == kExitOk) status = ExitCodeFor(e);
      ++failed;
      if (dynamic_cast<const Cancelled*>(&e)) break;
    }
  }
  if (args.sessions.size() > 1) {
    io.out << args.sessions.size() - static_cast<std::size_t>(failed) << " of "
           << args.sessions.size() << " sessions processed";
    if (failed > 0) io.out << ", " << failed << " failed";
    io.out << "\n";
  }
  return status;
}

}  // namespace

void AddReconstructCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<ReconstructArgs>();
  command.add_option("session", args->session, "session folder")->required();
  AddOptionFlags(&command, args->options, studio::ReconstructOptions::Fields());
  dispatch.On(&command, [args](Io& io) {
    CliProgress cli(io.err);
    PrintReconstruct(args->session,
                     studio::ReconstructSession(args->session, args->options, cli.progress()),
                     io.out);
    return kExitOk;
  });
}

void AddProcessCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<ProcessArgs>();
  args->command = &command;
  command.add_option("sessions", args->sessions, "session folders")->required();
  command.add_flag("--force", args->options.force, "run every stage, current or not");
  AddOptionFlags(&command, args->options.reconstruct,
                 studio::ReconstructOptions::Fields().Only({"faces", "choose-pose"}));
  AddOptionFlags(&command, args->options.texture, ProcessTextureFields());
  // Each texture or publish flag changes what it names; the rest is as the session was last
  // processed (RecordedExcludedViews, RecordedPublishOptions).
  AddOptionFlags(&command, args->options.publish, studio::PublishSessionOptions::Fields());
  AddNoPublishFlag(&command, &args->options.publish_model);
  dispatch.On(&command, [args](Io& io) { return RunProcess(*args, io); });
}

void AddPublishCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<PublishArgs>();
  args->command = &command;
  command.add_option("sessions", args->sessions, "session folders with a textured model")
      ->required();
  AddOptionFlags(&command, args->options, studio::PublishSessionOptions::Fields());
  command.add_option("--out", args->site,
                     "also copy each product into this static catalog site (SITE/<session>/, "
                     "SITE/index.html)");
  command.add_option("--site-title", args->site_title, "the catalog page's title")
      ->capture_default_str();
  dispatch.On(&command, [args](Io& io) {
    int status = kExitOk;
    for (const std::filesystem::path& session : args->sessions) {
      try {
        CliProgress cli(io.err);
        const studio::PublishSessionOptions options =
            WithGivenFlags(*args->command, studio::PublishSessionOptions::Fields(), args->options,
                           studio::RecordedPublishOptions(session));
        PrintPublish(
            session,
            studio::PublishSession(session, studio::ReadSession(session), options, cli.progress()),
            io.out);
        if (!args->site.empty()) {
          const studio::SiteResult site = studio::AddToSite(session, args->site, args->site_title);
          io.out << "site: " << site.product.folder.string() << " (" << site.product.files_written
                 << " files written, " << site.product.files_unchanged << " unchanged, "
                 << site.product.files_removed << " removed); "
                 << (args->site / "index.html").string() << " lists " << site.products
                 << (site.products == 1 ? " product\n" : " products\n");
        }
      } catch (const std::exception& e) {
        io.err << "carousel publish: " << session.string() << ": error: " << e.what() << '\n';
        if (status == kExitOk) status = ExitCodeFor(e);
        if (dynamic_cast<const Cancelled*>(&e)) break;
      }
    }
    return status;
  });
}

}  // namespace carousel::app
