// Built-in stages "deform": tbsp::LaplacianDeformer (pcl_ext/deform) under the constraints of a
// constraints JSON file (docs/constraints_json.md), and "tetdeform": tbsp::TetDeformer + transfer
// (the steps of `tbsp tetdeform`, tet_job_run.h) under a handles JSON (docs/tetdeform_json.md),
// applied to each frame's mesh. Only parameter mapping lives here; the files are read once and
// checked against each mesh they are applied to.
#include "stage_util.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/plugins/constraints_json.h"
#include "tbsp/plugins/json_file.h"
#include "tbsp/plugins/tet_job_run.h"

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

class TetDeform : public Stage {
public:
  explicit TetDeform(const Params& p)
      : files_(TetJobFiles::load(p.text("handles"), p.text("rigid"), p.text("stiffness"))), tets_(int(p.integer("tets"))),
        iterations_(int(p.integer("iterations"))), interpolation_(p.boolean("rotation_interpolation")) {}
  Ports process(FrameContext& ctx, const Ports& in) override {
    const auto& mesh = in.at("mesh").mesh;
    // the same mesh object as last frame (a constant source): the same result
    if (mesh == last_in_ && last_out_) return {{"mesh", Data::of(last_out_)}};
    const TetJobSetup setup = tet_job_setup(*mesh, tets_, "node '" + ctx.node + "' mesh");
    const TetJob job = files_.parse(setup.numInputVertices());  // indices checked against this mesh
    TetDeformer d;
    d.setMesh(setup.tets);
    d.setOptions(tet_job_options(job, interpolation_));
    apply_tet_job(setup, job, files_, d);
    d.setProgressCallback(ctx.progress);
    try {
      d.deform(iterations_ > 0 ? iterations_ : job.iterations.value_or(50));
    } catch (const InvalidInput& e) {
      throw InvalidInput(files_.handles + ": " + e.what());  // handle-set problems surface at the first solve
    }
    const TetDeformReport& r = d.report();
    ctx.numbers = {{"iterations", double(r.iterations)}, {"converged", r.converged ? 1.0 : 0.0}, {"volume_ratio", r.volume_ratio},
                   {"max_handle_residual", r.max_handle_residual}, {"tets", double(r.tets)}};
    last_in_ = mesh;
    last_out_ = std::make_shared<const TriMesh>(deformed_surface(setup, d));
    return {{"mesh", Data::of(last_out_)}};
  }

private:
  TetJobFiles files_;
  int tets_, iterations_;
  bool interpolation_;
  std::shared_ptr<const TriMesh> last_in_, last_out_;
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
  StageInfo t{"tetdeform", "tbsp::TetDeformer: volumetric as-rigid-as-possible deformation of each frame's closed mesh under "
                           "the handles of a JSON file, transferred to the full mesh (thesis ch. 7; docs/tet_deformation.md)"};
  t.params = {ParamSpec::input_path("handles", "handles JSON (docs/tetdeform_json.md)", true),
              ParamSpec::input_path("rigid", "rigid regions JSON {\"rigid\": [region, ...]}", false),
              ParamSpec::input_path("stiffness", "stiffness JSON {\"default\": s, \"regions\": [...]}", false),
              ParamSpec::integer("tets", "0", "target tetrahedron count (QEM decimation first); 0: full resolution", 0, 100000000),
              ParamSpec::integer("iterations", "0", "iterations; 0: the handles file's, else 50", 0, 100000),
              ParamSpec::boolean("rotation_interpolation", true, "step (III) of ch. 7 (false: off, as --no-rotation-interpolation)")};
  t.inputs = {{"mesh", DataType::Mesh, "a closed, manifold triangle mesh"}};
  t.outputs = {{"mesh", DataType::Mesh, "the deformed mesh (same connectivity)"}};
  r.add(t, [](const Params& p) { return std::make_unique<TetDeform>(p); });
}

}  // namespace tbsp::pipeline::builtin
