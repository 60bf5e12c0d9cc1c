// A third-party stage plugin as a user would write it (docs/plugins.md): one stage, "sample.scale",
// that scales a mesh about the origin. Built in the tree for tests/pipeline and, from the
// installed package, by tests/packaging/consumer (find_package(tbsp)).
#include <memory>

#include "tbsp/plugins/stage.h"

namespace {

class Scale : public tbsp::pipeline::Stage {
public:
  explicit Scale(double s) : s_(s) {}
  tbsp::pipeline::Ports process(tbsp::pipeline::FrameContext& ctx, const tbsp::pipeline::Ports& in) override {
    auto m = std::make_shared<tbsp::TriMesh>(*in.at("mesh").mesh);
    m->V *= s_;
    ctx.numbers["factor"] = s_;
    return {{"mesh", tbsp::pipeline::Data::of(std::shared_ptr<const tbsp::TriMesh>(m))}};
  }

private:
  double s_;
};

}  // namespace

TBSP_STAGE_PLUGIN(registry) {
  tbsp::pipeline::StageInfo info{"sample.scale", "scales a mesh about the origin (sample third-party plugin)"};
  info.params = {tbsp::pipeline::ParamSpec::real("factor", "2", "scale factor", 1e-6, 1e6)};
  info.inputs = {{"mesh", tbsp::pipeline::DataType::Mesh, "input mesh"}};
  info.outputs = {{"mesh", tbsp::pipeline::DataType::Mesh, "scaled mesh"}};
  registry.add(info, [](const tbsp::pipeline::Params& p) { return std::make_unique<Scale>(p.real("factor")); });
}
