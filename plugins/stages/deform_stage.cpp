// Built-in stage "deform": tbsp::LaplacianDeformer (pcl_ext/deform) under the constraints of a
// constraints JSON file (docs/constraints_json.md), applied to each frame's mesh. Only parameter
// mapping lives here; the file is read once and checked against each mesh it is applied to.
#include "stage_util.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/plugins/constraints_json.h"
#include "tbsp/plugins/json_file.h"

namespace tbsp::pipeline::builtin {
namespace {

class Deform : public Stage {
public:
  explicit Deform(const Params& p)
      : path_(p.text("constraints")), doc_(load_json_file(path_)), field_(p.boolean("rotation_field")), uniform_(p.boolean("uniform")) {}
  Ports process(FrameContext& ctx, const Ports& in) override {
    const TriMesh& mesh = *in.at("mesh").mesh;
    const DeformJob job = parse_constraints_json(doc_, mesh, path_);  // indices checked against this mesh
    if (job.constraints.empty()) throw InvalidInput(path_ + ": no constraints; at least one position constraint is needed");
    LaplacianDeformer d;
    d.setProgressCallback(ctx.progress);
    if (uniform_) d.setLaplacianWeights(LaplacianWeights::Uniform);
    else if (job.weights) d.setLaplacianWeights(*job.weights);
    d.setMesh(mesh);
    for (const auto& c : job.constraints) d.addConstraint(c);
    d.setUseRotationField(field_ || job.rotation_field.value_or(false));
    d.setScale(job.scale);
    auto out = std::make_shared<TriMesh>(mesh);
    out->V = d.deform();
    out->N.resize(0, 3);
    ctx.numbers = {{"max_residual", d.report().max_residual}, {"solve_seconds", d.report().t_solve}};
    return {{"mesh", Data::of(std::shared_ptr<const TriMesh>(out))}};
  }

private:
  std::string path_;
  nlohmann::json doc_;
  bool field_, uniform_;
};

}  // namespace

void register_deform_stages(Registry& r) {
  StageInfo s{"deform", "tbsp::LaplacianDeformer: deforms each frame's mesh under the constraints of a JSON file (thesis ch. 3)"};
  s.params = {ParamSpec::input_path("constraints", "constraints JSON (docs/constraints_json.md)", true),
              ParamSpec::boolean("rotation_field", false, "estimate and apply the rotation field (eq. 3.12)"),
              ParamSpec::boolean("uniform", false, "uniform instead of cotangent Laplacian weights")};
  s.inputs = {{"mesh", DataType::Mesh, "the mesh to deform"}};
  s.outputs = {{"mesh", DataType::Mesh, "the deformed mesh (same connectivity)"}};
  r.add(s, [](const Params& p) { return std::make_unique<Deform>(p); });
}

}  // namespace tbsp::pipeline::builtin
