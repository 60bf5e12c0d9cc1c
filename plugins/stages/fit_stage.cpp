// Built-in stage "fit": tbsp::TemplateFitting (pcl_ext/fitting) on each frame's cloud, warm-started
// from the previous frame's fit. Only parameter mapping and the warm start live here.
#include "stage_util.h"
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/plugins/fit_json.h"

namespace tbsp::pipeline::builtin {
namespace {

class Fit : public Stage {
public:
  explicit Fit(const Params& p) : warm_(p.boolean("warm_start")) {
    if (!p.text("markers").empty()) markers_ = load_markers_json(p.text("markers"));
    params_.max_match_distance = p.real("r_max");
    params_.max_iterations = int(p.integer("iterations"));
    params_.detail_rounds = int(p.integer("detail_rounds"));
    params_.pull_rounds = int(p.integer("pull_rounds"));
    params_.coarse_nodes = int(p.integer("coarse_nodes"));
    params_.estimate_scale = p.boolean("estimate_scale");
    params_.refine_rotations = p.boolean("refine_rotations");
  }
  Ports process(FrameContext& ctx, const Ports& in) override {
    const Data& cloud = in.at("cloud");
    const bool warm = warm_ && last_;
    const TriMesh& templ = warm ? *last_ : *in.at("template").mesh;
    FitParameters prm = params_;
    if (warm) {
      // The last fit already has the scan's size and place: no global scale, no alignment, no
      // second pass with markers taken from a first one; automatic coarse_nodes means the
      // coarse stage's 400-node graph, which follows the limbs' swing from frame to frame
      // (without it the fits drift: docs/pipelines.md, "Measured").
      prm.estimate_scale = false;
      prm.align_without_markers = false;
      prm.auto_markers = 0;
      if (prm.coarse_nodes == -1) prm.coarse_nodes = 400;
    }
    TriMesh out;
    auto run = [&](auto& fit) {
      fit.setInputTemplate(templ);
      // markers steer the first frame; warm-started frames start from the last fit instead, whose
      // vertices no longer sit where the markers' template vertices did
      if (!warm) fit.setMarkers(markers_);
      fit.setParameters(prm);
      fit.setProgressCallback(ctx.progress);
      return fit.reconstruct(out);
    };
    FitReport rep;
    if (cloud.has_normals) {
      TemplateFitting<pcl::PointNormal> fit;
      fit.setInputCloud(cloud.cloud);
      rep = run(fit);
    } else {
      pcl::PointCloud<pcl::PointXYZ>::Ptr xyz(new pcl::PointCloud<pcl::PointXYZ>);
      xyz->reserve(cloud.cloud->size());
      for (const auto& q : *cloud.cloud) xyz->push_back(pcl::PointXYZ(q.x, q.y, q.z));
      TemplateFitting<pcl::PointXYZ> fit;
      fit.setInputCloud(xyz);
      rep = run(fit);
    }
    ctx.numbers = {{"hausdorff_rel", rep.hausdorff_rel}, {"rms_rel", rep.rms / std::max(rep.bbox_diagonal, 1e-300)},
                   {"p99_rel", rep.p99 / std::max(rep.bbox_diagonal, 1e-300)}, {"iterations", double(rep.iterations)},
                   {"scale", rep.scale}, {"coverage_points", rep.coverage_points}, {"warm_start", warm ? 1.0 : 0.0},
                   {"unexplained_regions", double(rep.unexplained.size())},
                   {"unexplained_points", rep.unexplained.empty() ? 0.0 : double(rep.unexplained.front().points)}};
    auto mesh = std::make_shared<const TriMesh>(std::move(out));
    if (warm_) last_ = mesh;
    return {{"mesh", Data::of(mesh)}};
  }

  bool keeps_state() const override { return warm_; }
  // warm-started frames start from the last fit: the template is read by the first frame only
  bool needs_input(const std::string& port) const override { return port != "template" || !(warm_ && last_); }

private:
  bool warm_;
  std::vector<FitMarker> markers_;
  FitParameters params_;
  std::shared_ptr<const TriMesh> last_;
};

}  // namespace

void register_fit_stages(Registry& r) {
  StageInfo s{"fit", "tbsp::TemplateFitting: deforms the template onto each frame's cloud (thesis ch. 5; docs/fitting.md)"};
  s.params = {
      ParamSpec::input_path("markers", "markers JSON (docs/fit_json.md) for the first frame; without: rigid + scale alignment first", false),
      ParamSpec::boolean("warm_start", true,
                         "start each frame from the previous frame's fit (same connectivity; it is in place: no alignment, scale or "
                         "second pass, the coarse stage with one 400-node graph when coarse_nodes is -1)"),
      ParamSpec::real("r_max", "0", "final match radius r_max, cloud units (0: from the data)", 0, 1e30),
      ParamSpec::integer("iterations", "15", "max iterations of the iterative fit", 1, 1000),
      ParamSpec::integer("detail_rounds", "-1", "detail rounds after the fit (-1 automatic as in tbsp fit: 4 on templates of at most 20,000 vertices, else none; 0 off)", -1, 100),
      ParamSpec::integer("pull_rounds", "3", "without detail rounds: local rounds drawing in regions the fit left unexplained (0 off)", 0, 100),
      ParamSpec::integer("coarse_nodes", "-1",
                         "coarse stage for parts turned about joints: nodes of its deformation graph (-1 automatic as in tbsp fit: 400 "
                         "without markers, with markers the fits without and with it compared; 0 off; else >= 4, 400 measured)",
                         -1, 20000),
      ParamSpec::boolean("estimate_scale", true, "estimate a global scale on the first frame (§5.2)"),
      ParamSpec::boolean("refine_rotations", false, "re-estimate the rotation field from the fit")};
  s.inputs = {{"cloud", DataType::Cloud, "the scan of this frame"},
              {"template", DataType::Mesh, "the template (used by the first frame, or every frame without warm_start)"}};
  s.outputs = {{"mesh", DataType::Mesh, "the fitted template"}};
  s.frame_ordered = true;
  r.add(s, [](const Params& p) { return std::make_unique<Fit>(p); });
}

}  // namespace tbsp::pipeline::builtin
