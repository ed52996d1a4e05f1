// The camera configuration: libgphoto2's widget tree, the rig settings in it, the camera's own
// labels for a value, and the summary text.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <sstream>

#include "carousel/rig/camera_settings.h"
#include "gphoto_internal.h"

namespace carousel::rig {
namespace gphoto_internal {

const std::vector<std::string>& WidgetNames(const std::string& setting) {
  static const std::map<std::string, std::vector<std::string>> names = {
      {kSettingIso, {"iso", "exposureindex"}},
      {kSettingAperture, {"aperture", "f-number"}},
      {kSettingShutterSpeed, {"shutterspeed", "shutterspeed2", "exposuretime"}},
      {kSettingWhiteBalance, {"whitebalance"}},
      {kSettingImageFormat, {"imageformat", "imagequality", "compression"}},
      {kSettingCaptureTarget, {"capturetarget"}},
  };
  static const std::vector<std::string> none;
  const auto it = names.find(setting);
  return it == names.end() ? none : it->second;
}

}  // namespace gphoto_internal

namespace {

using gphoto_internal::Describe;
using gphoto_internal::WidgetNames;
using gphoto_internal::WidgetTree;

// A widget's value as text; false when the widget holds none (sections, buttons).
bool WidgetValue(CameraWidget* widget, std::string* value) {
  CameraWidgetType type;
  gp_widget_get_type(widget, &type);
  switch (type) {
    case GP_WIDGET_TEXT:
    case GP_WIDGET_RADIO:
    case GP_WIDGET_MENU: {
      const char* text = nullptr;
      if (gp_widget_get_value(widget, &text) < GP_OK || !text) return false;
      *value = text;
      return true;
    }
    case GP_WIDGET_RANGE: {
      float number = 0;
      if (gp_widget_get_value(widget, &number) < GP_OK) return false;
      std::ostringstream out;
      out << number;
      *value = out.str();
      return true;
    }
    case GP_WIDGET_TOGGLE: {
      int on = 0;
      if (gp_widget_get_value(widget, &on) < GP_OK) return false;
      *value = std::to_string(on);
      return true;
    }
    case GP_WIDGET_DATE: {
      int t = 0;
      if (gp_widget_get_value(widget, &t) < GP_OK) return false;
      *value = std::to_string(t);
      return true;
    }
    default:
      return false;
  }
}

std::vector<std::string> WidgetChoices(CameraWidget* widget) {
  std::vector<std::string> choices;
  const int n = gp_widget_count_choices(widget);
  for (int i = 0; i < n; ++i) {
    const char* choice = nullptr;
    if (gp_widget_get_choice(widget, i, &choice) == GP_OK && choice) choices.emplace_back(choice);
  }
  return choices;
}

void CollectWidgets(CameraWidget* widget, const std::string& prefix,
                    std::map<std::string, std::string>* values,
                    std::map<std::string, std::vector<std::string>>* choices) {
  const char* name = nullptr;
  gp_widget_get_name(widget, &name);
  const std::string path = prefix + "/" + (name ? name : "");
  std::string value;
  if (WidgetValue(widget, &value)) {
    (*values)[path] = value;
    CameraWidgetType type;
    gp_widget_get_type(widget, &type);
    if (choices && (type == GP_WIDGET_RADIO || type == GP_WIDGET_MENU)) {
      (*choices)[path] = WidgetChoices(widget);
    }
  }
  const int n = gp_widget_count_children(widget);
  for (int i = 0; i < n; ++i) {
    CameraWidget* child = nullptr;
    if (gp_widget_get_child(widget, i, &child) == GP_OK) {
      CollectWidgets(child, path, values, choices);
    }
  }
}

// The camera's own label for `value`: an exact match, else (case aside) the same text, else
// the label of the same number within 3 % ("1/125" is the camera's "0.0080s"). Empty: none.
std::string MatchChoice(const std::string& value, const std::vector<std::string>& choices) {
  for (const std::string& c : choices) {
    if (c == value) return c;
  }
  for (const std::string& c : choices) {
    if (c.size() == value.size() &&
        std::equal(c.begin(), c.end(), value.begin(), [](char a, char b) {
          return std::tolower(static_cast<unsigned char>(a)) ==
                 std::tolower(static_cast<unsigned char>(b));
        })) {
      return c;
    }
  }
  const std::optional<double> wanted = SettingLabelNumber(value);
  if (!wanted || *wanted <= 0) return {};
  for (const std::string& c : choices) {
    const std::optional<double> v = SettingLabelNumber(c);
    if (v && std::abs(*v - *wanted) <= 0.03 * *wanted) return c;
  }
  return {};
}

// The widget of a rig setting (or a libgphoto2 widget name when `raw`).
CameraWidget* FindWidget(CameraWidget* root, const std::string& name, bool raw,
                         std::string* found_name) {
  const std::vector<std::string> names = raw ? std::vector<std::string>{name} : WidgetNames(name);
  for (const std::string& n : names) {
    CameraWidget* widget = nullptr;
    if (gp_widget_get_child_by_name(root, n.c_str(), &widget) == GP_OK) {
      *found_name = n;
      return widget;
    }
  }
  return nullptr;
}

}  // namespace

void GPhotoCamera::Impl::GetConfig(WidgetTree* tree) {
  const int r = gp_camera_get_config(camera_, &tree->root, context_);
  if (r < GP_OK) {
    needs_reconnect_ = r != GP_ERROR_NOT_SUPPORTED;
    throw DeviceError(Where(), "cannot read the configuration: " + Describe(r));
  }
}

std::map<std::string, std::string> GPhotoCamera::Impl::DoSettings(Clock::time_point deadline) {
  EnsureOpen(deadline);
  WidgetTree tree;
  GetConfig(&tree);
  std::map<std::string, std::string> settings;
  for (const char* key : {kSettingIso, kSettingAperture, kSettingShutterSpeed, kSettingWhiteBalance,
                          kSettingImageFormat, kSettingCaptureTarget}) {
    std::string widget_name;
    std::string value;
    if (CameraWidget* w = FindWidget(tree.root, key, false, &widget_name);
        w && WidgetValue(w, &value)) {
      settings[key] = value;
    }
  }
  return settings;
}

void GPhotoCamera::Impl::DoSet(const std::string& name, const std::string& value, bool raw,
                               Clock::time_point deadline) {
  EnsureOpen(deadline);
  WidgetTree tree;
  GetConfig(&tree);
  std::string widget_name;
  CameraWidget* widget = FindWidget(tree.root, name, raw, &widget_name);
  if (!widget) {
    throw InvalidArgument(Where() + ": the camera has no setting '" + name + "'");
  }
  int readonly = 0;
  gp_widget_get_readonly(widget, &readonly);
  if (readonly) throw InvalidArgument(Where() + ": '" + name + "' is read-only");
  CameraWidgetType type;
  gp_widget_get_type(widget, &type);
  int r = GP_OK;
  if (type == GP_WIDGET_RADIO || type == GP_WIDGET_MENU) {
    const std::vector<std::string> choices = WidgetChoices(widget);
    const std::string label = MatchChoice(value, choices);
    if (label.empty()) {
      std::string list;
      for (const std::string& c : choices) list += (list.empty() ? "" : ", ") + c;
      throw InvalidArgument(Where() + ": '" + value + "' is not a value of " + name +
                            " (the camera offers: " + list + ")");
    }
    r = gp_widget_set_value(widget, label.c_str());
  } else if (type == GP_WIDGET_TEXT) {
    r = gp_widget_set_value(widget, value.c_str());
  } else if (type == GP_WIDGET_RANGE || type == GP_WIDGET_TOGGLE) {
    char* end = nullptr;
    const double number = std::strtod(value.c_str(), &end);
    if (end == value.c_str() || *end != '\0') {
      throw InvalidArgument(Where() + ": '" + value + "' is not a number for " + name);
    }
    if (type == GP_WIDGET_RANGE) {
      float min = 0;
      float max = 0;
      float step = 0;
      gp_widget_get_range(widget, &min, &max, &step);
      if (number < min || number > max) {
        throw InvalidArgument(Where() + ": " + name + " must be within " + std::to_string(min) +
                              ".." + std::to_string(max));
      }
      const float f = static_cast<float>(number);
      r = gp_widget_set_value(widget, &f);
    } else {
      const int on = number != 0 ? 1 : 0;
      r = gp_widget_set_value(widget, &on);
    }
  } else {
    throw InvalidArgument(Where() + ": '" + name + "' cannot be set");
  }
  if (r >= GP_OK) r = gp_camera_set_single_config(camera_, widget_name.c_str(), widget, context_);
  if (r == GP_ERROR_NOT_SUPPORTED) r = gp_camera_set_config(camera_, tree.root, context_);
  if (r < GP_OK) {
    throw DeviceError(Where(), "cannot set " + name + " to '" + value + "': " + Describe(r));
  }
}

std::map<std::string, std::string> GPhotoCamera::Impl::DoConfiguration(
    Clock::time_point deadline, std::map<std::string, std::vector<std::string>>* choices) {
  EnsureOpen(deadline);
  WidgetTree tree;
  GetConfig(&tree);
  std::map<std::string, std::string> values;
  CollectWidgets(tree.root, "", &values, choices);
  return values;
}

std::string GPhotoCamera::Impl::DoSummary(Clock::time_point deadline) {
  EnsureOpen(deadline);
  CameraText text;
  const int r = gp_camera_get_summary(camera_, &text, context_);
  if (r < GP_OK) {
    needs_reconnect_ = true;
    throw DeviceError(Where(), "cannot read the summary: " + Describe(r));
  }
  return text.text;
}

}  // namespace carousel::rig
