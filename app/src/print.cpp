#include "print.h"

#include <cmath>
#include <iomanip>

namespace carousel::app {

void PrintReconstruct(const std::filesystem::path& s, const studio::ReconstructResult& result,
                      std::ostream& out) {
  out << std::fixed << std::setprecision(2) << "masks " << (s / "masks").string() << ": "
      << result.views << " silhouettes (" << result.method
      << (result.given_masks > 0 ? ", " + std::to_string(result.given_masks) + " given" : "")
      << (result.redecided > 0
              ? ", " + std::to_string(result.redecided) + " repaired by the other views"
              : "")
      << "; " << result.seconds_silhouettes << " s)\n";
  for (const studio::PassOutcome& pass : result.passes)
    out << (pass.status == "registered" ? "registered " : "NOT USED: ") << pass.note << " ("
        << pass.views << " views)\n";
  out << std::fixed << std::setprecision(2) << "hull " << (s / "recon/hull.ply").string() << ": "
      << result.hull_faces << " faces, " << std::setprecision(3) << result.voxel_size_m * 1e3
      << " mm voxels (" << std::setprecision(2) << result.seconds_hull << " s)\n"
      << "mesh " << (s / "recon/mesh.ply").string() << ": " << result.mesh_faces << " faces ("
      << result.seconds_mesh << " s)\n";
  if (!result.agreement.empty()) {
    double mean = 0.0;
    const recon::SilhouetteAgreement* worst = &result.agreement.front();
    for (const recon::SilhouetteAgreement& a : result.agreement) {
      mean += a.mean_deviation_px / static_cast<double>(result.agreement.size());
      if (a.mean_deviation_px > worst->mean_deviation_px) worst = &a;
    }
    out << "mesh vs silhouettes: outline deviation " << mean << " px on average, worst "
        << worst->view << " " << worst->mean_deviation_px << " px (IoU " << std::setprecision(4)
        << worst->iou << ")\n";
  }
}

void PrintTexture(const std::filesystem::path& session, const studio::TextureSessionResult& r,
                  std::ostream& out) {
  out << std::fixed << std::setprecision(2) << "model " << r.files.obj.string() << ", "
      << r.files.glb.string() << ": " << r.faces << " faces, " << r.charts << " charts, " << r.size
      << "^2 texture from " << r.views << " views\n"
      << "grouping: " << r.grouping.corrected_faces << " faces moved off the background, "
      << r.grouping.uncorrectable_faces << " with background in every view, "
      << r.grouping.island_faces_switched << " island faces switched, "
      << r.grouping.coherence_faces_switched << " for coherence (" << r.grouping.patches
      << " patches of " << std::setprecision(1) << r.grouping.mean_patch_faces
      << std::setprecision(2) << " faces on average), " << r.grouping.unseen_faces
      << " seen by no view (filled from neighbours)\n"
      << "texel density: " << std::setprecision(1) << 100.0 * r.dense_fraction
      << " % of faces get at least one texel per photo pixel; " << r.blended_texels
      << " texels blended across seams\n"
      << std::setprecision(2) << "time: grouping " << r.seconds_grouping << " s, atlas "
      << r.seconds_atlas << " s, transfer " << r.seconds_transfer << " s, export "
      << r.seconds_export << " s (PNG " << r.files.seconds_png << " s, GLB " << r.files.seconds_glb
      << " s), total " << r.seconds_total << " s; report "
      << (session / "model" / "report.json").string() << "\n";
  for (const auto& h : r.held_out) {
    out << "held-out view " << h.view << ": PSNR " << h.psnr_db << " dB, SSIM "
        << std::setprecision(4) << h.ssim;
    if (h.has_reference) {
      out << ", silhouette IoU " << h.mask_agreement;
    } else {
      out << " (no mask: over the model's own silhouette)";
    }
    out << std::setprecision(2) << "\n";
  }
  if (!r.held_out.empty())
    out << "held-out mean: PSNR " << r.mean_psnr_db << " dB, SSIM " << std::setprecision(4)
        << r.mean_ssim << "\n";
  for (const std::string& w : r.warnings) out << "warning: " << w << "\n";
}

void PrintPublish(const std::filesystem::path& session, const studio::PublishSessionResult& r,
                  std::ostream& out) {
  const auto model = session / "model";
  out << std::fixed << std::setprecision(2) << "web GLB " << (model / "model.web.glb").string()
      << ": " << static_cast<double>(r.web.bytes) / 1e6 << " MB (texture " << r.web.texture_size
      << "^2 JPEG " << static_cast<double>(r.web.texture_bytes) / 1e6 << " MB, geometry "
      << static_cast<double>(r.web.geometry_bytes) / 1e3 << " kB of "
      << static_cast<double>(r.web.geometry_raw_bytes) / 1e3 << " kB); lossless GLB "
      << static_cast<double>(r.lossless_bytes) / 1e6 << " MB\n";
  if (!r.held_out_web.empty())
    out << "held-out mean PSNR: web " << r.mean_psnr_web_db << " dB, lossless "
        << r.mean_psnr_lossless_db << " dB\n";
  out << "catalog: " << r.cutouts << " cut-outs";
  if (r.spin_frames > 0)
    out << ", 360° set of " << r.spin_frames << " ("
        << (r.spin_from_photos ? "photos of camera " + std::to_string(r.spin_camera) : "renders")
        << ") in " << (model / "360.zip").string() << " and " << (model / "spin.webp").string();
  out << "\nviewer page: " << (model / "index.html").string() << ", report "
      << (model / "report.html").string() << "\n";
}

void PrintCalibration(const studio::CalibrateSessionResult& r, std::ostream& out) {
  const calib::RigCalibration& c = r.result.calibration;
  int used = 0;
  for (const calib::RigPhotoReport& p : r.result.photos) used += p.used;
  out << std::fixed << std::setprecision(3) << "rig calibration " << r.file.string() << ": "
      << c.cameras.size() << " camera(s), " << used << " of " << r.result.photos.size()
      << " photos, " << c.corners << " corners, " << c.rms_px << " px RMS\n";
  for (const calib::RigCameraCalibration& camera : c.cameras) {
    const CameraModel& m = camera.camera;
    const Eigen::Vector3d centre = m.Centre();
    out << std::setprecision(2) << "  " << camera.name << ": fx " << m.fx << " fy " << m.fy
        << " cx " << m.cx << " cy " << m.cy << " k1 " << std::setprecision(4) << m.distortion.k1
        << " k2 " << m.distortion.k2 << std::setprecision(1) << "; centre (" << centre.x() * 1e3
        << ", " << centre.y() * 1e3 << ", " << centre.z() * 1e3 << ") mm, " << std::setprecision(1)
        << std::hypot(centre.x(), centre.y()) * 1e3 << " mm from the axis; " << camera.views
        << " photos, " << std::setprecision(3) << camera.rms_px << " px RMS\n";
  }
  out << std::setprecision(4) << "  turntable: observed/reported angle " << c.angle_scale
      << ", largest deviation " << std::setprecision(3) << c.angle_residual_max_deg << " deg\n";
  for (const std::string& w : r.result.warnings) out << "  warning: " << w << "\n";
}

}  // namespace carousel::app
