// Camera settings as every camera backend names and writes them (part of carousel_rig_api: no
// third-party dependencies): the well-known setting names, and the reading of exposure labels
// such as "1/125" and "f/8". The simulated camera (sim/) reads its exposure from these labels;
// the libgphoto2 backend matches a requested value to the camera's own label by its number.
//
// Units: shutter speeds in seconds, apertures as f-numbers (focal length / aperture diameter).
// Numbers are decimal as std::strtod reads them in the "C" locale ("0.5", "2", "1e-3"; blanks
// before a number are skipped, nothing may follow it); a number that is not finite or is out of
// double's range is no number.
#pragma once

#include <optional>
#include <string_view>

namespace carousel::rig {

// Well-known setting names.
inline constexpr const char* kSettingIso = "iso";
inline constexpr const char* kSettingAperture = "aperture";
inline constexpr const char* kSettingShutterSpeed = "shutterspeed";
inline constexpr const char* kSettingWhiteBalance = "whitebalance";
inline constexpr const char* kSettingImageFormat = "imageformat";
inline constexpr const char* kSettingCaptureTarget = "capturetarget";

// The exposure time a shutter-speed label stands for, in seconds: "1/125" -> 0.008, "0.5" and
// "2" as written. Accepted: a number, or a fraction of two numbers with a denominator > 0.
// The range is the caller's to check ("0" and "-1" parse).
// \throw InvalidArgument naming the label when it is neither.
double ParseShutterSeconds(std::string_view label);

// The f-number an aperture label stands for: "f/8" and "8" -> 8, "f/5.6" -> 5.6. Accepted: a
// number, optionally after "f/". The range is the caller's to check.
// \throw InvalidArgument naming the label when it is not one.
double ParseApertureFNumber(std::string_view label);

// The number any setting label stands for, for matching a value against the labels a camera
// offers: "f/5.6" and "5.6" -> 5.6, "1/125" and "0.0080s" (libgphoto2's exposure time) -> 0.008,
// "400" -> 400. Accepted: ParseShutterSeconds's forms, optionally after "f/" and before a
// final "s". Empty, not an error, for a label that is no number ("auto", "daylight").
std::optional<double> SettingLabelNumber(std::string_view label);

}  // namespace carousel::rig
