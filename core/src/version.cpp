#include "carousel/core/version.h"

#include <OpenMesh/Core/System/config.h>
#include <Eigen/Core>
#include <opencv2/core/version.hpp>

namespace carousel {

std::string LibraryVersions() {
  return std::string("OpenCV ") + CV_VERSION + ", OpenMesh " +
         std::to_string((OM_VERSION >> 16) & 0xff) + "." +
         std::to_string((OM_VERSION >> 8) & 0xff) + ", Eigen " +
         std::to_string(EIGEN_WORLD_VERSION) + "." + std::to_string(EIGEN_MAJOR_VERSION) + "." +
         std::to_string(EIGEN_MINOR_VERSION);
}

}  // namespace carousel
