#include "carousel/rig/camera_settings.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <string>

#include "carousel/core/error.h"

namespace carousel::rig {
namespace {

// `text`, the whole of it, as a number (see the header); empty when it is anything else.
std::optional<double> ParseNumber(std::string_view text) {
  const std::string s(text);  // strtod needs the terminating NUL
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || end != s.c_str() + s.size() || errno == ERANGE || !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

// "a/b" with b > 0, or a number.
std::optional<double> ParseNumberOrFraction(std::string_view text) {
  const std::size_t slash = text.find('/');
  if (slash == std::string_view::npos) return ParseNumber(text);
  const std::optional<double> numerator = ParseNumber(text.substr(0, slash));
  const std::optional<double> denominator = ParseNumber(text.substr(slash + 1));
  if (!numerator || !denominator || *denominator <= 0) return std::nullopt;
  const double quotient = *numerator / *denominator;
  if (!std::isfinite(quotient)) return std::nullopt;
  return quotient;
}

std::string_view WithoutFPrefix(std::string_view label) {
  if (label.starts_with("f/")) label.remove_prefix(2);
  return label;
}

}  // namespace

double ParseShutterSeconds(std::string_view label) {
  const std::optional<double> seconds = ParseNumberOrFraction(label);
  CAROUSEL_THROW_IF(!seconds, InvalidArgument,
                    "shutter speed '" << label << "' is not a number of seconds (1/125, 0.5, 2)");
  return *seconds;
}

double ParseApertureFNumber(std::string_view label) {
  const std::optional<double> f_number = ParseNumber(WithoutFPrefix(label));
  CAROUSEL_THROW_IF(!f_number, InvalidArgument,
                    "aperture '" << label << "' is not an f-number (f/8, 5.6)");
  return *f_number;
}

std::optional<double> SettingLabelNumber(std::string_view label) {
  label = WithoutFPrefix(label);
  if (label.ends_with('s')) label.remove_suffix(1);
  return ParseNumberOrFraction(label);
}

}  // namespace carousel::rig
