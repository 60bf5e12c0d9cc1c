#pragma once
/// \file synth_studio.h
/// \brief Synthetic multi-view studio (thesis §6.1 / §9.2 setting) with ground truth: a
/// procedural humanoid with a skirt, animated by a scripted motion, rendered into k calibrated
/// cameras with a solid 3D texture that moves with the surface (so SIFT can track it),
/// silhouettes, optional image noise, ground-truth meshes per frame, marker trajectories (TRC)
/// and optional virtual range scans (partial noisy clouds with occlusion holes).
/// Deterministic for a given seed.

#include <cstdint>
#include <functional>
#include <string>

#include "tbsp/core/progress.h"
#include "tbsp/io/studio.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::synth {

/// The procedural performer (metres, y up, feet at y = 0, facing +z): torso, head, arms, legs
/// and a skirt (a closed flared body around the hips). `part` labels each vertex.
/// `folds` (metres, >= 0, default 0 = none) adds cloth-like detail along the normals: 12
/// vertical pleats on the skirt (amplitude growing from 0.3·folds at the waist to folds at the
/// hem), horizontal wrinkles on the torso (0.6·folds, 8 cm wavelength) and sleeves (0.4·folds,
/// 6 cm). They need detail >= 2 to be resolved (~1.2 cm edges on the torso).
struct Humanoid {
  TriMesh mesh;
  std::vector<int> part;  ///< 0 torso, 1 head, 2/3 left/right arm, 4/5 left/right leg, 6 skirt
};
Humanoid make_humanoid(int detail = 1, double folds = 0.0);

/// The scripted motion at time t (seconds): arms and legs swing (±30°/±20°, 1 Hz), the skirt
/// sways, the body turns slowly about the vertical axis and steps forward. Same vertex order.
TriMesh animate_humanoid(const Humanoid& h, double t);

struct StudioOptions {
  int cameras = 8;
  int width = 1004, height = 1004;  ///< thesis studio: 1004 x 1004
  int frames = 10;
  double frame_rate = 25.0;
  double image_noise = 0.0;   ///< Gaussian image noise, grey levels (0..255)
  int markers = 12;           ///< marker vertices (farthest-point sampled) written to markers.trc
  bool range_scans = false;   ///< also write scans/camK/FFFF.pcd from each camera
  /// also write the range scans as 16-bit depth images depth/camK/FFFF.png (depth along the
  /// optical axis in units of 0.2 mm, 0 = no data; image size and intrinsics of the scan: the
  /// camera's divided by scan_stride) — a depth-sensor recording with a known pose
  bool depth_images = false;
  double scan_noise = 0.002;  ///< range-scan noise along the rays (metres)
  int scan_stride = 2;
  int detail = 1;             ///< mesh resolution of the performer (0 coarse .. 3 fine)
  double folds = 0.0;         ///< amplitude of cloth folds, metres (0 = none, see make_humanoid)
  std::uint64_t seed = 1;
};

struct StudioResult {
  Studio studio;          ///< as written (studio.path = DIR/studio.yaml)
  int images_written = 0;
  int vertices = 0, faces = 0;
};

/// Renders the studio into `dir` (created if needed): studio.yaml, template.ply (rest pose),
/// images/camK/FFFF.png, silhouettes/camK/FFFF.png, gt/FFFF.ply, markers.trc [, scans/...].
/// Every file is written atomically; studio.yaml last, so an interrupted run leaves no
/// studio.yaml that points at missing frames. Throws InvalidInput on bad options, Cancelled
/// when `progress` returns false.
StudioResult write_synthetic_studio(const std::string& dir, const StudioOptions& options,
                                    const ProgressCallback& progress = {});

/// Renders any mesh sequence with constant connectivity into a studio the same way (solid
/// texture carried by `rest`'s positions, so it moves with the surface; the same lights):
/// `frame(f)` is frame f's mesh, f = 0..options.frames-1 (y up). The cameras stand on a ring of
/// radius 2 × the sequence's height around its bounding box, alternating heights, looking at its
/// centre. Writes studio.yaml, template.ply (= `rest`), images/, silhouettes/, gt/FFFF.ply [,
/// scans/]; no markers. Uses cameras, width, height, frames, frame_rate, image_noise,
/// range_scans, depth_images, scan_noise, scan_stride, seed of `options`. Throws InvalidInput on bad options
/// or a frame whose vertex or face count differs from `rest`'s.
StudioResult write_sequence_studio(const std::string& dir, const TriMesh& rest, const std::function<TriMesh(int)>& frame,
                                   const StudioOptions& options, const ProgressCallback& progress = {});

}  // namespace tbsp::synth
