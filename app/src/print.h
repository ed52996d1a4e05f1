// The lines a stage's result prints, the same from `run`, `process` and the stage's own
// command. Private to app/.
#pragma once

#include <filesystem>
#include <ostream>

#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/publish_session.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/texture_session.h"

namespace carousel::app {

void PrintReconstruct(const std::filesystem::path& session, const studio::ReconstructResult& result,
                      std::ostream& out);
void PrintTexture(const std::filesystem::path& session, const studio::TextureSessionResult& result,
                  std::ostream& out);
void PrintPublish(const std::filesystem::path& session, const studio::PublishSessionResult& result,
                  std::ostream& out);
void PrintCalibration(const studio::CalibrateSessionResult& result, std::ostream& out);

}  // namespace carousel::app
