#include "texture_cmds.h"

#include "command.h"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "progress_bar.h"
#include "tbsp/core/error.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/io/atomic_file.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/plugins/json_file.h"
#include "tbsp/plugins/preview_render.h"
#include "tbsp/plugins/texture_json.h"
#include "tbsp/plugins/texture_preview.h"

namespace fs = std::filesystem;

namespace tbsp::cli {

namespace {
cv::Mat read_image(const std::string& path, int flags, const std::string& what) {
  cv::Mat img;
  try {
    img = cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    throw FileError("'" + path + "': cannot read the " + what + ": " + e.what());
  }
  if (img.empty()) throw FileError("'" + path + "': cannot read the " + what + " (not an image OpenCV can decode: use PNG or JPEG)");
  return img;
}

void write_png(const std::string& path, const cv::Mat& img) {
  atomic_write_with(path, [&](const std::string& tmp) {
    std::vector<uchar> buf;
    if (!cv::imencode(".png", img, buf)) return false;
    std::ofstream out(tmp, std::ios::binary);
    out.write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(buf.size()));
    return static_cast<bool>(out);
  });
}
}  // namespace

void add_texture(CLI::App& app, TextureArgs& a, CLI::App*& sub) {
  sub = app.add_subcommand("texture", "inverse texture mapping: wrap an image onto a mesh from a few pixel<->vertex constraints (thesis ch. 4)");
  sub->add_option("--mesh", a.mesh, "target mesh (.ply .obj .off .vtk), manifold, any genus")->required()->check(CLI::ExistingFile);
  sub->add_option("--image", a.image, "texture image (PNG, JPEG)")->required()->check(CLI::ExistingFile);
  sub->add_option("--constraints", a.constraints, "constraints JSON (docs/texture_json.md), at least 3")->required()->check(CLI::ExistingFile);
  sub->add_option("--out", a.out, "textured mesh: OUT.obj + OUT.mtl + OUT.png (the texture)")->required();
  sub->add_option("--mask", a.mask, "sewing-pattern mask image (same size; non-black = pattern)")->check(CLI::ExistingFile);
  sub->add_option("--surface", a.surface, "also write the deformed image surface as a coloured mesh (.ply .obj .off .vtk); "
                                          "with --offset and --mask this is the draped garment");
  sub->add_option("--offset", a.offset, "draping (§4.4): offset along the mesh normals, in mesh units");
  sub->add_option("--omega", a.omega, "constraint weight (default 10, at least 0.001; large = hard)")->check(CLI::Range(0.001, 1e300));
  sub->add_option("--sigma", a.sigma, "match weight in the final deformation (default 1; small = smoother surface)")->check(CLI::NonNegativeNumber);
  sub->add_option("--epsilon", a.epsilon, "match threshold factor: eps = factor * bbox diagonal * k (default 0.01)")->check(CLI::PositiveNumber);
  sub->add_option("--max-solve-nodes", a.max_solve_nodes, "larger images are solved on a coarser grid (default 400000)")->check(CLI::Range(16L, 100000000L));
  sub->add_option("--max-geodesic-nodes", a.max_geodesic_nodes, "texture geodesics on at most this many nodes (default 70000)")->check(CLI::Range(16L, 100000000L));
  sub->add_flag("--plane-distances", a.plane, "match with flat-image distances instead of geodesics on the deformed image (Fig. 4.7 baseline)");
  sub->add_flag("--no-mismatch-detection", a.no_mismatch, "keep all distance channels (no 0.8/1.25 ratio test)");
  sub->add_option("--report", a.report, "JSON report: residuals, matched fraction, distortion, timings");
  sub->add_option("--render", a.render, "PNG: the textured mesh next to the deformed image surface, seen head-on");
  sub->add_flag("-q,--quiet", a.quiet, "no progress bar or summary");
}

int cmd_texture(const TextureArgs& a) {
  const TriMesh mesh = read_mesh(a.mesh);
  const cv::Mat img = read_image(a.image, cv::IMREAD_COLOR, "texture image");
  std::vector<std::uint8_t> mask;
  if (!a.mask.empty()) {
    const cv::Mat m = read_image(a.mask, cv::IMREAD_GRAYSCALE, "mask");
    if (m.cols != img.cols || m.rows != img.rows)
      throw FileError("'" + a.mask + "': the mask is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) + " but the image is " +
                      std::to_string(img.cols) + "x" + std::to_string(img.rows) + "; give a mask of the image's size");
    mask.resize(static_cast<std::size_t>(m.cols) * m.rows);
    for (int y = 0; y < m.rows; ++y)
      for (int x = 0; x < m.cols; ++x) mask[static_cast<std::size_t>(y) * m.cols + x] = m.at<uchar>(y, x) > 0;
  }
  const std::vector<TextureConstraint> cons = parse_texture_constraints(load_json_file(a.constraints), a.constraints);
  // Output paths: OUT.obj, OUT.mtl, OUT.png.
  fs::path obj(a.out);
  if (obj.extension() != ".obj") throw InvalidInput("--out '" + a.out + "': the textured mesh is written as OBJ; give a path ending in .obj");
  const fs::path mtl = fs::path(obj).replace_extension(".mtl"), tex = fs::path(obj).replace_extension(".png");

  InverseTextureMappingOptions o;
  o.omega = a.omega;
  o.sigma = a.sigma;
  o.epsilon_factor = a.epsilon;
  o.normal_offset = a.offset;
  o.max_solve_nodes = a.max_solve_nodes;
  o.max_geodesic_nodes = a.max_geodesic_nodes;
  o.mismatch_detection = !a.no_mismatch;
  o.surface_fit_report = !a.report.empty();
  o.match_distance = a.plane ? MatchDistance::ImagePlane : MatchDistance::DeformedSurface;
  ProgressBar bar(!a.quiet);
  o.progress = bar.callback();
  InverseTextureMapping itm(o);
  itm.setInputMesh(mesh);
  itm.setImageSize(img.cols, img.rows);
  itm.setMask(mask);
  itm.setConstraints(cons);
  TextureMappingResult r;
  try {
    r = itm.compute();
  } catch (const InvalidInput& e) {
    throw InvalidInput(a.constraints + " / " + a.mesh + ": " + e.what());
  }
  bar.finish();
  const TextureMappingReport& p = r.report;

  // Textured OBJ: OBJ texture coordinates have v up and pixel centres at (x+0.5)/W.
  Eigen::MatrixX2d uv(r.uv.rows(), 2);
  for (Eigen::Index i = 0; i < uv.rows(); ++i) {
    uv(i, 0) = (r.uv(i, 0) + 0.5) / img.cols;
    uv(i, 1) = 1.0 - (r.uv(i, 1) + 0.5) / img.rows;
  }
  write_png(tex.string(), img);
  write_textured_obj(obj.string(), mesh, uv, mtl.string(), "texture", tex.filename().string());

  const RgbImage rgb = read_rgb_image(a.image);  // the texture as RGB for colouring the outputs
  TriMesh surf;
  surf.V = r.surface;
  surf.F = r.surface_faces;
  surf.C.resize(surf.V.rows(), 3);
  for (Eigen::Index a2 = 0; a2 < surf.V.rows(); ++a2) surf.C.row(a2) = rgb.at(r.node_pixel(a2, 0), r.node_pixel(a2, 1));
  if (!a.surface.empty()) write_mesh(a.surface, surf);
  if (!a.render.empty()) {
    render_texture_result_png(a.render, mesh, r, rgb);
  }
  if (!a.report.empty()) {
    nlohmann::json j;
    j["mesh"] = a.mesh;
    j["output"] = a.out;
    j["image"] = {{"path", a.image}, {"width", img.cols}, {"height", img.rows}};
    j["constraints"] = p.constraints;
    j["vertices"] = p.mesh_vertices;
    j["grid_nodes"] = p.grid_nodes;
    j["geodesic_nodes"] = p.geodesic_nodes;
    j["pixels_per_node"] = p.pixels_per_node;
    j["constraint_residual_px"] = p.constraint_residual_px;
    j["max_constraint_residual_px"] = p.max_constraint_residual_px;
    j["matched_fraction"] = p.matched_fraction;
    j["matched"] = p.matched;
    j["unmatched"] = p.unmatched;
    j["dropped_channels"] = p.dropped_channels;
    j["epsilon"] = p.epsilon;
    j["uv_faces"] = p.uv_faces;
    j["flipped_uv_faces"] = p.flipped_uv_faces;
    j["angle_distortion_deg"] = {{"mean", p.angle_distortion_mean_deg}, {"p95", p.angle_distortion_p95_deg}};
    j["area_distortion_log"] = {{"mean", p.area_distortion_mean}, {"p95", p.area_distortion_p95}};
    j["roughness"] = {{"final", p.roughness}, {"initial", p.initial_roughness}};
    j["image_on_mesh"] = {{"cells", p.surface_cells_on_mesh}, {"angle_distortion_mean_deg", p.surface_angle_distortion_mean_deg},
                          {"area_distortion_log_mean", p.surface_area_distortion_mean}, {"mesh_to_surface_mean", p.mesh_to_surface_mean},
                          {"mesh_to_surface_max", p.mesh_to_surface_max}};
    j["timings_s"] = {{"deform1", p.t_deform1},   {"mesh_geodesics", p.t_mesh_geodesics}, {"texture_geodesics", p.t_texture_geodesics},
                      {"matching", p.t_matching}, {"deform2", p.t_deform2},               {"total", p.t_total}};
    j["options"] = {{"omega", a.omega}, {"sigma", a.sigma}, {"epsilon_factor", a.epsilon}, {"offset", a.offset},
                    {"distances", a.plane ? "image-plane" : "deformed-surface"}, {"mismatch_detection", !a.no_mismatch}};
    write_text_file_atomic(a.report, j.dump(2) + "\n");
  }
  if (!a.quiet)
    std::cout << "texture: " << p.constraints << " constraints, max residual " << p.max_constraint_residual_px << " px, "
              << 100 * p.matched_fraction << "% of " << p.mesh_vertices << " vertices matched, " << p.flipped_uv_faces
              << " flipped UV faces, " << p.t_total << " s -> " << obj.string() << "\n";
  return 0;
}

void add_texture_commands(CLI::App& app, CommandTable& table) {
  register_command<TextureArgs>(app, table, add_texture, cmd_texture);
}

}  // namespace tbsp::cli
