#pragma once
/// \file synthetic_scan.h
/// \brief Synthetic scans with ground truth from any mesh: a known smooth non-rigid deformation
/// (bend + twist + scale), area-uniform samples with Gaussian noise, uniform outliers, a hole,
/// optional misregistered fragments, and markers. Used by the tests, the benchmarks, the sample
/// data (`tbsp synth-scan`) and the demo. Deterministic for a given seed.
#include <Eigen/Core>
#include <limits>
#include <vector>

#include "tbsp/fitting/template_fitter.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::synth {

/// \brief One joint of an articulated deformation: the part of the mesh on the positive side
/// of the plane through `centre` with normal `side` turns by `angle_deg` about the line through
/// `centre` along `axis`; across ±`falloff` (length) of that plane the angle blends smoothly
/// (smoothstep), so the surface bends instead of tearing. Joints apply in order (a later
/// joint's part is moved by the earlier ones first: give parents before children). With a
/// finite `seed`, only the part connected (through mesh edges between vertices on the turning
/// side) to the vertex nearest the seed turns: one limb, not everything beyond the plane.
struct Joint {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d side = Eigen::Vector3d::UnitY();
  double falloff = 0.01;
  double angle_deg = 0;
  Eigen::Vector3d seed = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

/// \brief Applies the joints to V (template coordinates), each about its centre as moved by
/// the joints before it. \throws InvalidInput for a joint with a seed (those need the faces) or
/// a seed with no vertex on the joint's turning side.
Eigen::MatrixX3d articulate(const Eigen::MatrixX3d& V, const std::vector<Joint>& joints);
/// \brief The same with the faces, which joints with a seed need.
Eigen::MatrixX3d articulate(const Eigen::MatrixX3d& V, const Eigen::MatrixX3i& F, const std::vector<Joint>& joints);

/// \brief Joints of the libigl bunny (bunny.off, the bun_zipper frame): the head with its ears
/// nods about the neck, then the ears tilt about their base, both by `angle_deg`.
std::vector<Joint> bunny_head_and_ears(double angle_deg);

/// \brief Joints of the libigl Armadillo (armadillo.obj, 43k vertices, y up): the right forearm
/// raised, the left one lowered, the left knee straightened, each by `angle_deg`
/// (one limb each: the joints carry seeds; use articulate(V, F, joints)).
std::vector<Joint> armadillo_limbs(double angle_deg);

/// \brief Joints of the SMPL human in T-pose (odedstein meshes human_man.obj / human_woman.obj,
/// 6890 vertices, metres, y up, face +z): the left arm lowered and the right arm raised at the
/// shoulder, the head nodding, the right knee bending, each by `angle_deg` (with seeds).
std::vector<Joint> human_limbs(double angle_deg);

struct ScenarioOptions {
  double bend_deg = 60, twist_deg = 60, scale = 2.0;
  Eigen::Vector3d translation = Eigen::Vector3d(0.3, -0.2, 0.1);  // × template bbox diagonal
  int points = 30000;
  double noise = 0.002;            // Gaussian σ as a fraction of the target's bbox diagonal
  double outliers = 0.10;          // fraction of the final cloud that is uniform outliers
  double hole = 0.25;              // fraction of the surface area removed
  int hole_axis = 1;               // the hole lies beyond a plane across this principal axis of the
                                   // template (0: longest, 1: second, 2: shortest)
  int markers = 20;
  double fragment_offset = 0.0;    // > 0: split the cloud in two halves, shift one by this × diag
  unsigned seed = 1;
  std::vector<Joint> joints;       // articulation applied before bend / twist / scale (set those to 0 / 1)
};

struct Scenario {
  TriMesh templ;                   // the undeformed real mesh
  Eigen::MatrixX3d target;         // ground truth: deformed template vertices
  Eigen::MatrixX3d P, N;           // the cloud (inliers then outliers, shuffled deterministically)
  std::vector<char> inlier;        // per cloud point
  Eigen::MatrixX3d clean;          // noise-free position of each inlier point (rows as P; outliers NaN)
  std::vector<char> hole_vertex;   // template vertices whose whole one-ring lies in the hole
  double hole_area_fraction = 0;
  std::vector<FitMarker> markers;
  double diag = 0;                 // target bbox diagonal
};

/// Smooth non-rigid deformation: rotation about the centre by angles that vary along the
/// principal axis (bend about a perpendicular axis + twist about the principal axis), then
/// uniform scale and translation.
Eigen::MatrixX3d bend_twist_scale(const Eigen::MatrixX3d& V, const ScenarioOptions& o);

Scenario make_scenario(const TriMesh& templ, const ScenarioOptions& o);

/// \brief Turns a whole scenario (truth, cloud, clean samples, normals, free marker positions)
/// by `deg` about the axis (1, 2, 0.5) through the truth's centre: with a small translation and
/// scale in the options, a template "roughly in place" as a user without markers has it.
void turn_scenario(Scenario& s, double deg);

struct ScenarioErrors {
  double hausdorff_clean_rel;      // max distance of noise-free inlier samples to the fit / diag
  double hausdorff_noisy_rel;      // same with the noisy inlier points
  double hole_mean_rel;            // mean |fit - truth| over hole vertices / diag
  double all_mean_rel;             // mean |fit - truth| over all vertices / diag
};

/// Errors of a fitted mesh with the template's connectivity.
ScenarioErrors evaluate(const Scenario& s, const TriMesh& fit);

}  // namespace tbsp::synth
