#include "carousel/gui/studio_args.h"

#include <algorithm>
#include <fstream>
#include <sstream>

#include "carousel/core/error.h"
#include "carousel/core/options.h"
#include "carousel/studio/defaults.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/sim_capture.h"

namespace carousel::gui {
namespace {

// The described options the window takes, bound to one RunOptions.
struct Tables {
  OptionTable<studio::SimCaptureOptions> sim =
      studio::SimCaptureOptions::Fields().Only(studio::RunSimFieldNames());
  OptionTable<studio::TextureSessionOptions> texture =
      studio::TextureSessionOptions::Fields().Only({"exclude-views"});
  const OptionTable<studio::PublishSessionOptions>& publish =
      studio::PublishSessionOptions::Fields();
  const OptionTable<studio::CalibrationPlan>& plan = studio::CalibrationPlan::Fields();
  OptionTable<studio::ReconstructOptions> reconstruct =
      studio::ReconstructOptions::Fields().Only({"pose-by-colour"});
};

const Tables& TheTables() {
  static const Tables tables;
  return tables;
}

// Sets the field named `name` ("no-<name>" for a bool on by default) in one of the tables;
// `value` is null for a flag without a value. Returns false when no table has it.
template <typename Owner>
bool SetFrom(const OptionTable<Owner>& table, Owner& object, const std::string& name,
             const std::string* value, bool* needs_value) {
  for (const OptionField<Owner>& field : table.fields()) {
    const OptionInfo& info = field.info;
    const std::string off = info.negative_name.empty() ? "no-" + info.name : info.negative_name;
    const bool is_bool = !field.is_choice() && std::holds_alternative<bool*>(field.ref(object));
    if (is_bool && (name == info.name || name == off)) {
      *needs_value = false;
      *std::get<bool*>(field.ref(object)) = name == info.name;
      return true;
    }
    if (name != info.name) continue;
    *needs_value = true;
    if (value != nullptr) SetOptionText(field, object, *value);
    return true;
  }
  return false;
}

void ParseSize(const std::string& text, int* width, int* height) {
  studio::ParseImageSize(text, "--window", width, height);
}

template <typename Owner>
void AppendUsage(std::ostringstream& out, const OptionTable<Owner>& table, const Owner& object) {
  for (const OptionField<Owner>& field : table.fields()) {
    const OptionInfo& info = field.info;
    std::string range = info.RangeText();
    if (!info.choices.empty()) {
      range.clear();
      for (std::size_t i = 0; i < info.choices.size(); ++i)
        range += (i == 0 ? "" : ", ") + info.choices[i];
    }
    out << "  --" << info.name << "  " << info.help;
    if (!range.empty()) out << " (" << range << ")";
    const std::string current = GetOptionText(field, object);
    if (!current.empty()) out << " [" << current << "]";
    out << "\n";
  }
}

}  // namespace

StudioArgs ParseStudioArgs(const std::vector<std::string>& args) {
  StudioArgs out;
  out.run.sim.data_dir = studio::DefaultDataDir();
  const Tables& tables = TheTables();
  bool sim = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    CAROUSEL_THROW_IF(arg.rfind("--", 0) != 0, InvalidArgument,
                      "carousel-studio takes no positional arguments, got '" << arg << "'");
    std::string name = arg.substr(2), inline_value;
    bool has_inline = false;
    if (const auto eq = name.find('='); eq != std::string::npos) {
      inline_value = name.substr(eq + 1);
      name = name.substr(0, eq);
      has_inline = true;
    }
    // The value of a flag that takes one: "--x=v" or the next argument.
    auto value = [&]() -> std::string {
      if (has_inline) return inline_value;
      CAROUSEL_THROW_IF(i + 1 >= args.size(), InvalidArgument, "--" << name << " needs a value");
      return args[++i];
    };
    if (name == "help") {
      out.help = true;
    } else if (name == "version") {
      out.version = true;
    } else if (name == "sim") {
      sim = true;
    } else if (name == "rig") {
      out.rig = value();
    } else if (name == "product") {
      out.products.push_back(value());
    } else if (name == "out") {
      out.run.out = value();
    } else if (name == "operator") {
      out.operator_mode = true;
    } else if (name == "calibration") {
      out.calibration = true;
    } else if (name == "autorun") {
      out.autorun = true;
    } else if (name == "autorun-choose-pose") {
      const std::string text = value();
      std::size_t used = 0;
      try {
        out.autorun_pose = std::stoi(text, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      CAROUSEL_THROW_IF(
          used == 0 || used != text.size() || out.autorun_pose < 1, InvalidArgument,
          "--autorun-choose-pose needs a pose number, 1 or more, got '" << text << "'");
    } else if (name == "quit-when-done") {
      out.quit_when_done = true;
    } else if (name == "screenshot-dir") {
      out.screenshot_dir = value();
    } else if (name == "frame-log") {
      out.frame_log = value();
    } else if (name == "window") {
      ParseSize(value(), &out.width, &out.height);
    } else if (name == "no-publish") {
      out.run.publish_model = false;
    } else if (name == "force") {
      out.run.force = true;
    } else {
      bool needs_value = false;
      std::string text;
      // Look the name up first without consuming a value (bools take none).
      const bool known =
          SetFrom(tables.sim, out.run.sim, name, nullptr, &needs_value) ||
          SetFrom(tables.texture, out.run.texture, name, nullptr, &needs_value) ||
          SetFrom(tables.publish, out.run.publish, name, nullptr, &needs_value) ||
          SetFrom(tables.reconstruct, out.run.reconstruct, name, nullptr, &needs_value);
      CAROUSEL_THROW_IF(!known, InvalidArgument,
                        "unknown flag '" << arg << "' (carousel-studio --help lists them)");
      if (needs_value) {
        text = value();
        (void)(SetFrom(tables.sim, out.run.sim, name, &text, &needs_value) ||
               SetFrom(tables.texture, out.run.texture, name, &text, &needs_value) ||
               SetFrom(tables.publish, out.run.publish, name, &text, &needs_value) ||
               SetFrom(tables.plan, out.plan, name, &text, &needs_value));
      }
    }
  }
  CAROUSEL_THROW_IF(sim && !out.rig.empty(), InvalidArgument,
                    "--sim and --rig exclude each other: the simulated rig or the rig file's");
  CAROUSEL_THROW_IF(out.autorun && out.products.empty() && !out.calibration, InvalidArgument,
                    "--autorun needs --product SKU (the button presses it)");
  CAROUSEL_THROW_IF(!out.operator_mode && out.products.size() > 1, InvalidArgument,
                    "several --product values are for --operator (one press each)");
  if (!out.rig.empty()) out.run.hardware = studio::ReadRigConfig(out.rig);
  if (!out.products.empty()) out.run.product = out.products.front();
  out.plan.Validate();
  if (!out.run.product.empty()) {
    out.run.Validate();
  } else {
    out.run.sim.Validate();
    out.run.texture.Validate();
    out.run.publish.Validate();
  }
  return out;
}

std::string StudioUsage() {
  std::ostringstream out;
  out << "carousel-studio: the photographer's window (capture and build, photos, model, "
         "report, sessions)\n\n"
         "Usage: carousel-studio [--sim | --rig RIG.json] [--product SKU] [--out DIR] [options]\n\n"
         "  --sim  the simulated rig (the default)\n"
         "  --rig RIG.json  the studio's turntable and cameras (carousel sim rig writes one)\n"
         "  --product SKU  the product's SKU (repeat it with --operator --autorun)\n"
         "  --out DIR  folder of the sessions [sessions]\n"
         "  --operator  operator mode: full screen, SKU entry, one big button\n"
         "  --autorun  press the button for each --product (with --calibration: run the "
         "calibration wizard)\n"
         "  --calibration  the calibration wizard's session (the board on the table)\n"
         "  --autorun-choose-pose K  when a pass's pose is ambiguous, choose pose K (as the "
         "button under its picture does)\n"
         "  --quit-when-done  exit when the autorun's sessions have ended\n"
         "  --screenshot-dir DIR  a PNG of the window at each stage change and at the end\n"
         "  --frame-log FILE  one frame time per line (ms)\n"
         "  --window WxH  window size [1280x800]\n"
         "  --no-publish  stop after the texture stage\n"
         "  --force  start the session over (the old one is kept beside it)\n\n"
         "Capture (the simulated rig) and output:\n";
  const Tables& tables = TheTables();
  StudioArgs defaults;
  defaults.run.sim.data_dir = studio::DefaultDataDir();
  AppendUsage(out, tables.sim, defaults.run.sim);
  AppendUsage(out, tables.texture, defaults.run.texture);
  AppendUsage(out, tables.publish, defaults.run.publish);
  AppendUsage(out, tables.reconstruct, defaults.run.reconstruct);
  out << "\nCalibration (with --calibration):\n";
  AppendUsage(out, tables.plan, defaults.plan);
  return out.str();
}

FrameStats SummarizeFrameTimes(std::vector<double> ms) {
  FrameStats stats;
  stats.frames = static_cast<int>(ms.size());
  if (ms.empty()) return stats;
  std::sort(ms.begin(), ms.end());
  const auto at = [&ms](double p) {
    const auto k = static_cast<std::size_t>(std::ceil(p * static_cast<double>(ms.size())));
    return ms[std::min(ms.size() - 1, k == 0 ? 0 : k - 1)];
  };
  stats.p50_ms = at(0.5);
  stats.p99_ms = at(0.99);
  stats.max_ms = ms.back();
  return stats;
}

std::vector<double> ReadFrameLog(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw IoError(file, "cannot read the frame log");
  std::vector<double> ms;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    std::istringstream parse(line);
    double value = 0.0;
    if (!(parse >> value) || !(value >= 0.0))
      throw FormatError(file,
                        "line " + std::to_string(number) + " is not a frame time: '" + line + "'");
    ms.push_back(value);
  }
  return ms;
}

}  // namespace carousel::gui
