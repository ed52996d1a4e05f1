// Routes OpenMesh's global omerr()/omlog() streams into Carousel (private to core).
//
// OpenMesh writes diagnostics to process-global multiplexed streams. They are connected here
// once per process: omerr() text goes into the active capture (so that a read error can quote
// it) or, outside a capture, to Carousel's log as a warning; omlog() chatter goes to the debug
// log. OpenMesh's default std::cerr targets are disconnected (OpenMesh leaks the disconnected
// target object once; tests/lsan.supp names it).
#pragma once

#include <mutex>
#include <string>

namespace carousel::internal {

// Holds OpenMesh's I/O lock for its lifetime and collects omerr() text written meanwhile.
class OpenMeshCapture {
 public:
  OpenMeshCapture();
  ~OpenMeshCapture();
  OpenMeshCapture(const OpenMeshCapture&) = delete;
  OpenMeshCapture& operator=(const OpenMeshCapture&) = delete;
  // The omerr() text so far, newlines replaced by spaces.
  std::string Text();

 private:
  std::unique_lock<std::mutex> lock_;
};

}  // namespace carousel::internal
