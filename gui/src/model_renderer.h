// The model view's OpenGL part: the prepared model (model_view.h) in vertex buffers, drawn into
// an offscreen framebuffer that the Model panel shows as an image. Private to gui/.
#pragma once

#include <string>

#include "carousel/gui/model_view.h"
#include "gl.h"

namespace carousel::gui {

class ModelRenderer {
 public:
  ModelRenderer() = default;
  ~ModelRenderer();
  ModelRenderer(const ModelRenderer&) = delete;
  ModelRenderer& operator=(const ModelRenderer&) = delete;

  // Compiles the shaders (once a GL context is current). Returns false with `error` set.
  bool Init(std::string* error);
  // Replaces the model on the GPU.
  void Upload(const ModelMesh& mesh);
  bool has_model() const { return vertices_ > 0; }
  // Draws into the offscreen target of `width` x `height` pixels; its colour texture is
  // color_texture() (bottom row first, as GL stores it).
  void Render(const OrbitCamera& camera, ModelMode mode, int width, int height);
  GLuint color_texture() const { return color_; }

 private:
  void Resize(int width, int height);
  void Release();
  void WarmUp();

  GLuint program_ = 0, vao_ = 0, texture_ = 0;
  GLuint buffers_[5] = {0, 0, 0, 0, 0};
  GLint u_mvp_ = -1, u_mode_ = -1, u_light_ = -1, u_texture_ = -1, u_flat_ = -1;
  int vertices_ = 0;
  GLuint fbo_ = 0, color_ = 0, depth_ = 0;
  int width_ = 0, height_ = 0;
  float near_ = 0.01f, far_ = 10.0f;
  float radius_ = 0.1f;
};

}  // namespace carousel::gui
