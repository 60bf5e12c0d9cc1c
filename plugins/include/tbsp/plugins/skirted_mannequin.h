#pragma once
/// \file skirted_mannequin.h
/// \brief Ground truth for the cloth stages (thesis ch. 10): a mannequin built from a skeleton
/// (a tapered tube around each limb and torso bone, radii known) wearing a skirt (an open flared
/// tube hanging from the waist), and the mesh sequence of that mannequin driven by a BVH clip with
/// the skirt simulated by PbdClothSimulator (known material, known proxies = the limb tubes).
/// Used by tests and benchmarks of segmentation, proxies and parameter estimation.

#include <functional>
#include <vector>

#include "tbsp/cloth/animatable_model.h"
#include "tbsp/cloth/collision_proxies.h"
#include "tbsp/cloth/pbd_cloth_simulator.h"
#include "tbsp/cloth/skeleton.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::synth {

struct MannequinOptions {
  int tube_segments = 16;        ///< vertices around each limb tube
  double tube_ring_spacing = 0.03;  ///< metres between rings along a bone
  int skirt_rings = 30;          ///< rings from waist to hem
  int skirt_segments = 72;       ///< vertices around the skirt
  double skirt_top = 0.10;       ///< waist height above the root joint, metres
  double skirt_length = 0.40;    ///< metres
  double waist_radius = 0.18;    ///< metres
  double hem_radius = 0.34;      ///< metres
};

/// The mannequin in the skeleton's rest pose (metres, as the skeleton). Limbs whose joint names
/// match a table (CMU / Mixamo-style names: thigh, shin, foot, buttock, abdomen, chest, neck,
/// collar, shoulder, forearm) get tubes; fingers, eyes and end sites do not. Where tubes overlap,
/// the faces with a corner inside another tube are removed (a scan has no inner surfaces); the
/// seams stay open by up to one ring of faces (a few cm, like the holes of a real scan).
struct SkirtedMannequin {
  TriMesh mesh;                 ///< body tubes, then the skirt (vertices skirt_begin..end)
  Eigen::Index skirt_begin = 0; ///< first skirt vertex
  Eigen::VectorXi cloth;        ///< ground-truth label: 1 for the moving skirt (rings ≥ 2), else 0
  Eigen::VectorXd clothness;    ///< simulation δ: 0 body and waist ring, 0.5 ring 1, 1 below
  SkinningWeights weights;      ///< rigid: each tube vertex to its bone's joint, the skirt to the root
  std::vector<CollisionProxy> limbs;  ///< the tubes as cones (exact radii), one per tube
};

/// \throws InvalidInput when the skeleton has no limb the table knows, or options are out of range.
SkirtedMannequin make_skirted_mannequin(const Skeleton& skeleton, const MannequinOptions& options = {});

struct SkirtSequenceOptions {
  int frames = 200;          ///< frames produced
  int bvh_step = 3;          ///< BVH frames per produced frame (120 Hz CMU clips -> 40 Hz)
  int first_bvh_frame = 0;
  double bvh_scale = 0.01;   ///< BVH units -> metres (the CMU clips in ../shared/data are in cm)
  int settle_frames = 40;    ///< frames simulated in the first pose before frame 0 is emitted
  ClothMaterial material;    ///< the true ρ
  PbdSettings settings;      ///< time_step is set to bvh_step · the BVH frame time
};

/// \brief The model that generates the ground truth: the mannequin's mesh (rest pose), its rigid
/// weights and true clothness, the limb tubes as proxies, `material` and `settings`.
AnimatableModel generating_model(const SkirtedMannequin& m, const Skeleton& skeleton, const ClothMaterial& material, const PbdSettings& settings);

/// \brief Drives the mannequin with the clip: an AnimatableModel with the mannequin's rigid
/// weights, `clothness`, the limb tubes as proxies and the true material, played by
/// ModelAnimator (the body skinned, the skirt simulated — the same simulation the parameter
/// estimation searches with); calls `frame(n, V)` with the whole mesh of every produced frame
/// (same vertex order as m.mesh). Deterministic.
/// \throws InvalidInput when the clip lacks a joint of the skeleton (names must match) or has
/// fewer frames than requested.
void simulate_skirt_sequence(const SkirtedMannequin& m, const Skeleton& skeleton, const BvhMotion& clip,
                             const SkirtSequenceOptions& options,
                             const std::function<void(int, const Eigen::MatrixX3d&)>& frame);

}  // namespace tbsp::synth
