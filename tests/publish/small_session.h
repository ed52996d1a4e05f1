// The small simulated session publish_test and catalog_test share: made once per CTest run by
// `carousel run --sim` (8 stops of the shoe at 648x432, view 3 held out), published at sizes
// that suit its photos.
#pragma once

#include <filesystem>
#include <string>

#include "carousel/testing/testing.h"

namespace carousel::publish {

inline constexpr int kSmallCutoutSize = 640;
// The publish flags the session was made with (pass them to a `carousel publish` of a copy to
// get the same files).
inline const std::string kSmallPublishFlags =
    "--cutout-size 640 --spin-size 320 --hero-size 640 "
    "--poster-size 320";

inline std::filesystem::path SmallSession() {
  return testing::SimulatedSession(
      "publish-small-session", "tiny",
      "--scene shoe --views 8 --size 648x432 --exclude-views 3 " + kSmallPublishFlags);
}

}  // namespace carousel::publish
