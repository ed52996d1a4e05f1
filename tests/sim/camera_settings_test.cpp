// The exposure-label parser both camera backends read settings with (carousel_rig_api).
#include "carousel/rig/camera_settings.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "carousel/core/error.h"

namespace carousel::rig {
namespace {

using ::testing::DoubleNear;
using ::testing::HasSubstr;
using ::testing::Optional;

TEST(CameraSettingsTest, ShutterLabelsReadAsSeconds) {
  EXPECT_DOUBLE_EQ(ParseShutterSeconds("1/125"), 1.0 / 125.0);
  EXPECT_DOUBLE_EQ(ParseShutterSeconds("0.5"), 0.5);
  EXPECT_DOUBLE_EQ(ParseShutterSeconds("2"), 2.0);
  EXPECT_DOUBLE_EQ(ParseShutterSeconds("1/4000"), 0.00025);
  for (const char* bad : {"", "fast", "1/0", "1/125x", "1x/125", "1/2/3", "inf", "1/"}) {
    EXPECT_THROW(ParseShutterSeconds(bad), InvalidArgument) << bad;
  }
  EXPECT_THAT([] { ParseShutterSeconds("1/125x"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("'1/125x'")));
}

TEST(CameraSettingsTest, ApertureLabelsReadAsFNumbers) {
  EXPECT_DOUBLE_EQ(ParseApertureFNumber("f/8"), 8.0);
  EXPECT_DOUBLE_EQ(ParseApertureFNumber("5.6"), 5.6);
  for (const char* bad : {"", "f/", "f8x", "wide", "nan"}) {
    EXPECT_THROW(ParseApertureFNumber(bad), InvalidArgument) << bad;
  }
}

TEST(CameraSettingsTest, AnyLabelMatchesByItsNumber) {
  EXPECT_THAT(SettingLabelNumber("f/5.6"), Optional(DoubleNear(5.6, 1e-12)));
  EXPECT_THAT(SettingLabelNumber("0.0080s"), Optional(DoubleNear(0.008, 1e-12)));
  EXPECT_THAT(SettingLabelNumber("1/125"), Optional(DoubleNear(0.008, 1e-12)));
  EXPECT_THAT(SettingLabelNumber("400"), Optional(DoubleNear(400.0, 1e-12)));
  EXPECT_EQ(SettingLabelNumber("auto"), std::nullopt);
  EXPECT_EQ(SettingLabelNumber("daylight"), std::nullopt);
  EXPECT_EQ(SettingLabelNumber("inf"), std::nullopt);
}

}  // namespace
}  // namespace carousel::rig
