#include "model_renderer.h"

#include <algorithm>
#include <vector>

namespace carousel::gui {
namespace {

// Unlit texture (as a viewer shows the model) or a flat colour lit by a headlight; the
// wireframe pass draws lines in one colour.
constexpr const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec2 uv;
layout(location = 3) in vec3 chart_rgb;
layout(location = 4) in vec3 density_rgb;
uniform mat4 mvp;
uniform int mode;
out vec3 v_normal;
out vec2 v_uv;
out vec3 v_rgb;
void main() {
  gl_Position = mvp * vec4(position, 1.0);
  v_normal = normal;
  v_uv = uv;
  v_rgb = mode == 2 ? chart_rgb : (mode == 3 ? density_rgb : vec3(0.8));
}
)";

constexpr const char* kFragmentShader = R"(#version 330 core
in vec3 v_normal;
in vec2 v_uv;
in vec3 v_rgb;
uniform int mode;
uniform vec3 light;
uniform sampler2D albedo;
uniform vec4 flat_rgba;
out vec4 colour;
void main() {
  if (flat_rgba.a > 0.0) { colour = flat_rgba; return; }
  if (mode == 0) { colour = vec4(texture(albedo, v_uv).rgb, 1.0); return; }
  float lambert = abs(dot(normalize(v_normal), light));
  colour = vec4(v_rgb * (0.35 + 0.65 * lambert), 1.0);
}
)";

GLuint Compile(GLenum type, const char* source, std::string* error) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (ok == GL_FALSE) {
    char log[1024] = {0};
    glGetShaderInfoLog(shader, sizeof(log) - 1, nullptr, log);
    *error = std::string("shader: ") + log;
    glDeleteShader(shader);
    return 0;
  }
  return shader;
}

void Buffer(GLuint buffer, GLuint location, int components, const std::vector<float>& data) {
  glBindBuffer(GL_ARRAY_BUFFER, buffer);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(data.size() * sizeof(float)), data.data(),
               GL_STATIC_DRAW);
  glEnableVertexAttribArray(location);
  glVertexAttribPointer(location, components, GL_FLOAT, GL_FALSE, 0, nullptr);
}

}  // namespace

GLuint UploadTexture(const cv::Mat& rgba, bool mipmaps) {
  if (rgba.empty() || rgba.type() != CV_8UC4) return 0;
  const cv::Mat packed = rgba.isContinuous() ? rgba : rgba.clone();
  GLuint texture = 0;
  glGenTextures(1, &texture);
  glBindTexture(GL_TEXTURE_2D, texture);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, packed.cols, packed.rows, 0, GL_RGBA, GL_UNSIGNED_BYTE,
               packed.data);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  if (mipmaps) {
    glGenerateMipmap(GL_TEXTURE_2D);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  } else {
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  }
  glBindTexture(GL_TEXTURE_2D, 0);
  return texture;
}

GLuint UploadTexture(const cv::Mat& rgba, const std::vector<cv::Mat>& mips) {
  const GLuint texture = UploadTexture(rgba, false);
  if (texture == 0 || mips.empty()) return texture;
  glBindTexture(GL_TEXTURE_2D, texture);
  for (std::size_t i = 0; i < mips.size(); ++i) {
    const cv::Mat level = mips[i].isContinuous() ? mips[i] : mips[i].clone();
    glTexImage2D(GL_TEXTURE_2D, static_cast<GLint>(i + 1), GL_RGBA8, level.cols, level.rows, 0,
                 GL_RGBA, GL_UNSIGNED_BYTE, level.data);
  }
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAX_LEVEL, static_cast<GLint>(mips.size()));
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
  glBindTexture(GL_TEXTURE_2D, 0);
  return texture;
}

ModelRenderer::~ModelRenderer() {
  Release();
  if (fbo_ != 0) glDeleteFramebuffers(1, &fbo_);
  if (color_ != 0) glDeleteTextures(1, &color_);
  if (depth_ != 0) glDeleteRenderbuffers(1, &depth_);
  if (program_ != 0) glDeleteProgram(program_);
}

bool ModelRenderer::Init(std::string* error) {
  const GLuint vs = Compile(GL_VERTEX_SHADER, kVertexShader, error);
  const GLuint fs = vs != 0 ? Compile(GL_FRAGMENT_SHADER, kFragmentShader, error) : 0;
  if (vs == 0 || fs == 0) return false;
  program_ = glCreateProgram();
  glAttachShader(program_, vs);
  glAttachShader(program_, fs);
  glLinkProgram(program_);
  glDeleteShader(vs);
  glDeleteShader(fs);
  GLint ok = 0;
  glGetProgramiv(program_, GL_LINK_STATUS, &ok);
  if (ok == GL_FALSE) {
    char log[1024] = {0};
    glGetProgramInfoLog(program_, sizeof(log) - 1, nullptr, log);
    *error = std::string("shader program: ") + log;
    return false;
  }
  u_mvp_ = glGetUniformLocation(program_, "mvp");
  u_mode_ = glGetUniformLocation(program_, "mode");
  u_light_ = glGetUniformLocation(program_, "light");
  u_texture_ = glGetUniformLocation(program_, "albedo");
  u_flat_ = glGetUniformLocation(program_, "flat_rgba");
  WarmUp();
  return true;
}

void ModelRenderer::WarmUp() {
  // One small triangle drawn in every mode: Mesa's llvmpipe compiles a shader variant the first
  // time each state is drawn, which would otherwise cost the frame that first shows a model.
  ModelMesh tiny;
  tiny.positions = {0, 0, 0, 0.1f, 0, 0, 0, 0.1f, 0};
  tiny.normals = {0, 0, 1, 0, 0, 1, 0, 0, 1};
  tiny.uvs = {0, 0, 1, 0, 0, 1};
  tiny.chart_rgb = tiny.density_rgb = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  tiny.texture_rgba = cv::Mat(4, 4, CV_8UC4, cv::Scalar(128, 128, 128, 255));
  tiny.texture_mips = {cv::Mat(2, 2, CV_8UC4, cv::Scalar(128, 128, 128, 255)),
                       cv::Mat(1, 1, CV_8UC4, cv::Scalar(128, 128, 128, 255))};
  tiny.center = Eigen::Vector3f(0.03f, 0.03f, 0.0f);
  tiny.radius = 0.1f;
  Upload(tiny);
  OrbitCamera camera;
  camera.Frame(tiny.center, tiny.radius);
  for (int m = 0; m < kModelModes; ++m) Render(camera, static_cast<ModelMode>(m), 64, 64);
  glFinish();
  Release();
}

void ModelRenderer::Release() {
  if (vao_ != 0) glDeleteVertexArrays(1, &vao_);
  if (buffers_[0] != 0) glDeleteBuffers(5, buffers_);
  if (texture_ != 0) glDeleteTextures(1, &texture_);
  vao_ = texture_ = 0;
  std::fill(std::begin(buffers_), std::end(buffers_), 0u);
  vertices_ = 0;
}

void ModelRenderer::Upload(const ModelMesh& mesh) {
  Release();
  glGenVertexArrays(1, &vao_);
  glBindVertexArray(vao_);
  glGenBuffers(5, buffers_);
  Buffer(buffers_[0], 0, 3, mesh.positions);
  Buffer(buffers_[1], 1, 3, mesh.normals);
  Buffer(buffers_[2], 2, 2, mesh.uvs);
  Buffer(buffers_[3], 3, 3, mesh.chart_rgb);
  Buffer(buffers_[4], 4, 3, mesh.density_rgb);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  texture_ = UploadTexture(mesh.texture_rgba, mesh.texture_mips);
  vertices_ = static_cast<int>(mesh.positions.size() / 3);
  radius_ = std::max(mesh.radius, 1e-3f);
}

void ModelRenderer::Resize(int width, int height) {
  if (width == width_ && height == height_ && fbo_ != 0) return;
  if (fbo_ == 0) {
    glGenFramebuffers(1, &fbo_);
    glGenTextures(1, &color_);
    glGenRenderbuffers(1, &depth_);
  }
  glBindTexture(GL_TEXTURE_2D, color_);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glBindTexture(GL_TEXTURE_2D, 0);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, color_, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  width_ = width;
  height_ = height;
}

void ModelRenderer::Render(const OrbitCamera& camera, ModelMode mode, int width, int height) {
  width = std::max(width, 1);
  height = std::max(height, 1);
  Resize(width, height);
  GLint previous_fbo = 0;
  glGetIntegerv(GL_FRAMEBUFFER_BINDING, &previous_fbo);
  GLint previous_viewport[4];
  glGetIntegerv(GL_VIEWPORT, previous_viewport);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, width, height);
  glClearColor(0.16f, 0.17f, 0.19f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  if (vertices_ > 0) {
    glEnable(GL_DEPTH_TEST);
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glDisable(GL_SCISSOR_TEST);
    glUseProgram(program_);
    const float near_m = std::max(1e-3f, camera.distance - 2.0f * radius_);
    const float far_m = camera.distance + 2.0f * radius_;
    const Eigen::Matrix4f mvp =
        camera.ProjectionMatrix(static_cast<float>(width) / static_cast<float>(height), near_m,
                                far_m) *
        camera.ViewMatrix();
    glUniformMatrix4fv(u_mvp_, 1, GL_FALSE, mvp.data());
    const Eigen::Vector3f light = (camera.Eye() - camera.target).normalized();
    glUniform3f(u_light_, light.x(), light.y(), light.z());
    glUniform1i(u_texture_, 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glBindVertexArray(vao_);
    const int shade_mode = mode == ModelMode::kWireframe ? 1 : static_cast<int>(mode);
    glUniform1i(u_mode_, shade_mode);
    glUniform4f(u_flat_, 0, 0, 0, 0);
    if (mode == ModelMode::kWireframe) {
      glEnable(GL_POLYGON_OFFSET_FILL);
      glPolygonOffset(1.0f, 1.0f);
    }
    glDrawArrays(GL_TRIANGLES, 0, vertices_);
    if (mode == ModelMode::kWireframe) {
      glDisable(GL_POLYGON_OFFSET_FILL);
      glPolygonMode(GL_FRONT_AND_BACK, GL_LINE);
      glUniform4f(u_flat_, 0.1f, 0.1f, 0.12f, 1.0f);
      glDrawArrays(GL_TRIANGLES, 0, vertices_);
      glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    }
    glBindVertexArray(0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glUseProgram(0);
    glDisable(GL_DEPTH_TEST);
  }
  glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(previous_fbo));
  glViewport(previous_viewport[0], previous_viewport[1], previous_viewport[2],
             previous_viewport[3]);
}

}  // namespace carousel::gui
