#pragma once
/// \file skirt_studio.h
/// \brief Ground truth for the cloth parameter estimation (thesis §10.7, issue 26): the skirted
/// mannequin driven by a BVH clip with a known material (skirted_mannequin.h), rendered into a
/// calibrated multi-view studio with a textured surface (synth_studio.h), and the animatable
/// model our pipeline builds from the simulated meshes alone (segmentation §10.3, bone-heat
/// weights, fitted proxies §10.4) — the input of ClothParameterEstimation, which then sees
/// only the rendered images, the silhouettes and the skeleton motion.

#include <string>
#include <vector>

#include "tbsp/cloth/animatable_model.h"
#include "tbsp/core/progress.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/plugins/skirted_mannequin.h"
#include "tbsp/plugins/synth_studio.h"

namespace tbsp::synth {

struct SkirtStudioOptions {
  MannequinOptions mannequin;
  SkirtSequenceOptions sequence;  ///< frames, BVH range and step, the true material
  StudioOptions studio;           ///< cameras, image size, noise (frames and frame rate are set from `sequence`)
};

struct SkirtStudio {
  SkirtedMannequin mannequin;
  Skeleton skeleton;
  std::vector<SkeletonPose> poses;  ///< the skeleton motion, one pose per studio frame
  std::vector<Eigen::MatrixX3d> frames;  ///< the simulated meshes (= gt/FFFF.ply), the reference sequence
  StudioResult studio;              ///< studio.yaml, images, silhouettes, gt/ (the simulated meshes)
  AnimatableModel model;            ///< built from the simulated meshes by the pipeline; material = the default ClothMaterial
};

/// \brief Simulates, renders into `dir` and builds the model. Deterministic.
/// \throws InvalidInput on bad options or a clip the mannequin cannot be built from (see
/// make_skirted_mannequin, simulate_skirt_sequence), FileError when `dir` cannot be written.
SkirtStudio write_skirt_studio(const std::string& dir, const BvhMotion& clip, const SkirtStudioOptions& options,
                               const ProgressCallback& progress = {});

/// \brief The model of a template (`rest`, in the skeleton's rest pose) with its segmentation
/// (σ, NaN = no opposite surface, counted as 0; δ): bone-heat skinning weights, collision proxies
/// fitted with σ (`proxies` options), one region with the default material, `time_step` seconds
/// per frame (`tbsp cloth build`). \throws InvalidInput as the steps do.
AnimatableModel build_animatable_model(const TriMesh& rest, const Skeleton& skeleton, const Eigen::VectorXd& sigma,
                                       const Eigen::VectorXd& clothness, const ProxyFitOptions& proxies, double time_step);

/// \brief The same from a mesh sequence (constant connectivity, frame 0 = `rest`): the clothness
/// by ClothSegmentation over `frames` first (`tbsp cloth segment` + `tbsp cloth build`).
AnimatableModel build_animatable_model(const TriMesh& rest, const std::vector<Eigen::MatrixX3d>& frames, const Skeleton& skeleton,
                                       double time_step);

}  // namespace tbsp::synth
