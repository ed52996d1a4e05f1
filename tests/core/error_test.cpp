#include "carousel/core/error.h"

#include <gtest/gtest.h>

#include "carousel/testing/testing.h"

namespace carousel {
namespace {

TEST(ErrorTest, HierarchyLetsCallersCatchByKind) {
  EXPECT_THROW(throw FormatError("a.ply", "truncated"), IoError);
  EXPECT_THROW(throw FormatError("a.ply", "truncated"), Error);
  EXPECT_THROW(throw DeviceError("/dev/ttyACM0", "unplugged"), Error);
  EXPECT_THROW(throw Cancelled(), Error);
  EXPECT_THROW(throw InvalidArgument("x"), Error);
}

TEST(ErrorTest, MessagesNameThePathOrDevice) {
  const FormatError format("/tmp/x/mesh.ply", "truncated");
  EXPECT_STREQ(format.what(), "/tmp/x/mesh.ply: truncated");
  EXPECT_EQ(format.path(), "/tmp/x/mesh.ply");
  EXPECT_EQ(format.reason(), "truncated");
  const DeviceError device("ptpip:127.0.0.1", "camera busy");
  EXPECT_STREQ(device.what(), "ptpip:127.0.0.1: camera busy");
  EXPECT_EQ(device.device(), "ptpip:127.0.0.1");
}

int CheckedDivide(int a, int b) {
  CAROUSEL_CHECK(b != 0, "dividing " << a << " by zero");
  return a / b;
}

TEST(ErrorTest, CheckThrowsInternalErrorWithLocationAndMessage) {
  EXPECT_EQ(CheckedDivide(6, 3), 2);
  try {
    CheckedDivide(7, 0);
    FAIL() << "no exception";
  } catch (const InternalError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("error_test.cpp:"), std::string::npos) << message;
    EXPECT_NE(message.find("b != 0"), std::string::npos) << message;
    EXPECT_NE(message.find("dividing 7 by zero"), std::string::npos) << message;
  }
}

TEST(ErrorTest, ThrowIfThrowsTheGivenTypeOnlyWhenTrue) {
  auto validate = [](int count) {
    CAROUSEL_THROW_IF(count < 1, InvalidArgument, "Options.count must be >= 1, got " << count);
  };
  EXPECT_NO_THROW(validate(1));
  CAROUSEL_EXPECT_THROW_WITH(validate(0), InvalidArgument, "Options.count must be >= 1, got 0");
}

}  // namespace
}  // namespace carousel
