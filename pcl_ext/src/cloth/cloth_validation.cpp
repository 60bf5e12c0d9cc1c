// The light, dependency-free checks of the cloth types (linked by the parser fuzzer, which loads
// model files without the simulator or the weight solver).
#include <cmath>
#include <string>

#include "tbsp/cloth/animatable_model.h"
#include "tbsp/core/error.h"

namespace tbsp {

void validate_pbd_settings(const PbdSettings& s, const char* where) {
  auto bad = [&](const std::string& what) { throw InvalidInput(std::string("[") + where + "] " + what); };
  if (s.iterations < 1 || s.iterations > 1000) bad("iterations must be in 1..1000");
  if (s.substeps < 1 || s.substeps > 64) bad("substeps must be in 1..64");
  if (!(s.time_step > 0) || !std::isfinite(s.time_step)) bad("time_step must be > 0 seconds");
  if (!s.gravity.allFinite()) bad("gravity must be finite");
  if (!(s.drag_constant >= 0) || !(s.drag_unit > 0) || !std::isfinite(s.drag_constant + s.drag_unit)) bad("drag_constant must be ≥ 0 and drag_unit > 0");
  if (!(s.k_stretch >= 0 && s.k_stretch <= 1)) bad("k_stretch must be in [0, 1]");
  if (!(s.thickness >= 0) || !std::isfinite(s.thickness)) bad("thickness must be ≥ 0");
  if (s.contact_interval < 1 || s.contact_interval > 64) bad("contact_interval must be in 1..64");
  if (!(s.tether_slack >= 0 && s.tether_slack <= 1)) bad("tether_slack must be in [0, 1]");
  if (!(s.friction >= 0 && s.friction <= 2) || !(s.restitution >= 0 && s.restitution <= 1))
    bad("friction must be in [0, 2] and restitution in [0, 1]");
}

void AnimatableModel::validate(const char* where) const {
  const std::string w = std::string("[") + where + "] ";
  const Eigen::Index n = mesh.V.rows();
  if (n == 0 || mesh.F.rows() == 0) throw InvalidInput(w + "the model has no mesh");
  if (!mesh.V.allFinite()) throw InvalidInput(w + "the mesh has non-finite vertex coordinates");
  if (mesh.F.minCoeff() < 0 || mesh.F.maxCoeff() >= n) throw InvalidInput(w + "a face index is out of range");
  validate_skeleton(skeleton, where);
  if (weights.rows() != n || weights.cols() != skeleton.numJoints())
    throw InvalidInput(w + "skinning weights are " + std::to_string(weights.rows()) + " x " + std::to_string(weights.cols()) +
                       ", expected #vertices (" + std::to_string(n) + ") x #joints (" + std::to_string(skeleton.numJoints()) + ")");
  for (Eigen::Index i = 0; i < n; ++i) {
    double sum = 0;
    for (SkinningWeights::InnerIterator it(weights, i); it; ++it) {
      if (!(it.value() >= 0) || !std::isfinite(it.value())) throw InvalidInput(w + "vertex " + std::to_string(i) + " has a negative or non-finite weight");
      sum += it.value();
    }
    if (std::abs(sum - 1) > 1e-6)
      throw InvalidInput(w + "the weights of vertex " + std::to_string(i) + " sum to " + std::to_string(sum) + ", not 1");
  }
  if (clothness.size() != n) throw InvalidInput(w + "clothness has " + std::to_string(clothness.size()) + " values for " + std::to_string(n) + " vertices");
  for (Eigen::Index i = 0; i < n; ++i)
    if (!(clothness(i) >= 0 && clothness(i) <= 1)) throw InvalidInput(w + "vertex " + std::to_string(i) + " has clothness outside [0, 1]");
  if (materials.empty()) throw InvalidInput(w + "no cloth material (need one per region)");
  if (region.size() && region.size() != n) throw InvalidInput(w + "region has " + std::to_string(region.size()) + " labels for " + std::to_string(n) + " vertices");
  if (region.size() && (region.minCoeff() < 0 || region.maxCoeff() >= int(materials.size())))
    throw InvalidInput(w + "a region label has no material (labels 0.." + std::to_string(materials.size() - 1) + ")");
  for (const auto& m : materials)
    if (!(m.d_n >= 0) || !(m.d_t >= 0) || !std::isfinite(m.d_n + m.d_t) || !(m.k_bend >= 0 && m.k_bend <= 1))
      throw InvalidInput(w + "a material is out of range (finite d_n, d_t ≥ 0, k_bend in [0, 1])");
  for (const auto& p : proxies)
    if (p.bone.joint < 0 || p.bone.joint >= skeleton.numJoints() || !p.cone.a.allFinite() || !p.cone.b.allFinite() || !(p.cone.ra >= 0) ||
        !(p.cone.rb >= 0))
      throw InvalidInput(w + "a collision proxy has a bad joint index or cone");
}

}  // namespace tbsp
