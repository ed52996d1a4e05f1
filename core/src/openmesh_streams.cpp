#include "openmesh_streams.h"

#include <algorithm>
#include <iostream>

#include <OpenMesh/Core/System/omstream.hh>

#include "carousel/core/logging.h"

namespace carousel::internal {
namespace {

struct Router {
  std::mutex io_mutex;    // serialises OpenMesh I/O (global reader registry and streams)
  std::mutex text_mutex;  // guards `capturing` and `captured`
  bool capturing = false;
  std::string captured;

  void Error(const std::string& text) {
    std::lock_guard<std::mutex> lock(text_mutex);
    if (capturing) {
      captured += text;
      return;
    }
    if (!text.empty() && text != "\n") CAROUSEL_LOG_WARN("OpenMesh: " << text);
  }
  void Chatter(const std::string& text) {
    if (!text.empty() && text != "\n") CAROUSEL_LOG_DEBUG("OpenMesh: " << text);
  }
};

Router& GetRouter();

struct ErrorSink {};
struct ChatterSink {};
void operator<<(ErrorSink&, const std::string& text) { GetRouter().Error(text); }
void operator<<(ChatterSink&, const std::string& text) { GetRouter().Chatter(text); }

Router& GetRouter() {
  static Router router;
  static ErrorSink error_sink;
  static ChatterSink chatter_sink;
  static const bool connected = [] {
    omerr().disconnect(std::cerr);
    omerr().connect(error_sink);
    omlog().disconnect(std::cerr);
    omlog().disconnect(std::clog);
    omlog().connect(chatter_sink);
    omout().disconnect(std::cout);
    omout().connect(chatter_sink);
    return true;
  }();
  (void)connected;
  return router;
}

}  // namespace

OpenMeshCapture::OpenMeshCapture() : lock_(GetRouter().io_mutex) {
  Router& router = GetRouter();
  std::lock_guard<std::mutex> lock(router.text_mutex);
  router.capturing = true;
  router.captured.clear();
}

OpenMeshCapture::~OpenMeshCapture() {
  omerr().flush();
  Router& router = GetRouter();
  std::lock_guard<std::mutex> lock(router.text_mutex);
  router.capturing = false;
  router.captured.clear();
}

std::string OpenMeshCapture::Text() {
  omerr().flush();
  Router& router = GetRouter();
  std::lock_guard<std::mutex> lock(router.text_mutex);
  std::string text = router.captured;
  std::replace(text.begin(), text.end(), '\n', ' ');
  while (!text.empty() && text.back() == ' ') text.pop_back();
  return text;
}

}  // namespace carousel::internal
