// Built-in stage "texture": tbsp::InverseTextureMapping (pcl_ext/fitting, thesis ch. 4) wraps an
// image onto each frame's mesh from a few pixel <-> vertex constraints; the mesh leaves with
// per-vertex colours from the image at the vertices' texture coordinates (for a textured OBJ
// with the full-resolution image use `tbsp texture`). Only parameter mapping lives here.
#include "stage_util.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/plugins/json_file.h"
#include "tbsp/plugins/texture_json.h"
#include "tbsp/plugins/texture_preview.h"

namespace tbsp::pipeline::builtin {
namespace {

class Texture : public Stage {
public:
  explicit Texture(const Params& p)
      : constraints_path_(p.text("constraints")), image_(read_rgb_image(p.text("image"))),
        constraints_(parse_texture_constraints(load_json_file(constraints_path_), constraints_path_)) {
    o_.omega = p.real("omega");
    o_.sigma = p.real("sigma");
    o_.normal_offset = p.real("offset");
  }
  Ports process(FrameContext& ctx, const Ports& in) override {
    const TriMesh& mesh = *in.at("mesh").mesh;
    InverseTextureMappingOptions o = o_;
    o.progress = ctx.progress;
    InverseTextureMapping itm(o);
    itm.setInputMesh(mesh);
    itm.setImageSize(image_.width, image_.height);
    itm.setConstraints(constraints_);
    TextureMappingResult r;
    try {
      r = itm.compute();
    } catch (const InvalidInput& e) {
      throw InvalidInput(constraints_path_ + ": " + e.what());
    }
    auto out = std::make_shared<TriMesh>(mesh);
    out->C.resize(mesh.V.rows(), 3);
    for (Eigen::Index i = 0; i < mesh.V.rows(); ++i)
      out->C.row(i) = std::isfinite(r.uv(i, 0)) && std::isfinite(r.uv(i, 1)) ? image_.at(r.uv(i, 0), r.uv(i, 1))
                                                                               : Eigen::RowVector3d::Constant(0.5);  // unmatched: grey
    const TextureMappingReport& rep = r.report;
    ctx.numbers = {{"max_constraint_residual_px", rep.max_constraint_residual_px}, {"matched_fraction", rep.matched_fraction},
                   {"flipped_uv_faces", double(rep.flipped_uv_faces)}, {"seconds", rep.t_total}};
    return {{"mesh", Data::of(std::shared_ptr<const TriMesh>(out))}};
  }

private:
  std::string constraints_path_;
  RgbImage image_;
  std::vector<TextureConstraint> constraints_;
  InverseTextureMappingOptions o_;
};

}  // namespace

void register_texture_stages(Registry& r) {
  StageInfo s{"texture", "tbsp::InverseTextureMapping: wraps an image onto each frame's mesh from pixel <-> vertex constraints "
                         "(thesis ch. 4); the mesh gets per-vertex colours from the image"};
  s.params = {ParamSpec::input_path("image", "the texture image (PNG, JPEG)", true),
              ParamSpec::input_path("constraints", "constraints JSON (docs/texture_json.md), at least 3", true),
              ParamSpec::real("omega", "10", "constraint weight (large = hard; below ~1e-4 the constraints are lost)", 1e-3, 1e12),
              ParamSpec::real("sigma", "1", "match weight in the final deformation (small = smoother)", 0, 1e12),
              ParamSpec::real("offset", "0", "draping (§4.4): offset along the mesh normals, mesh units", -1e12, 1e12)};
  s.inputs = {{"mesh", DataType::Mesh, "a manifold mesh, any genus"}};
  s.outputs = {{"mesh", DataType::Mesh, "the same mesh with per-vertex colours from the image (grey where unmatched)"}};
  r.add(s, [](const Params& p) { return std::make_unique<Texture>(p); });
}

}  // namespace tbsp::pipeline::builtin
