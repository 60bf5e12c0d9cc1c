#pragma once
/// \file pbd_cloth_simulator.h
/// \brief Position-based cloth simulation (Müller et al. 2007) as used in thesis §10.5–§10.6:
/// stretch (eq. 10.2) and bending (eq. 10.3) constraints, collisions with capped-cone proxies
/// and self-collisions (spatial hashing), blend constraints towards the skinned pose (eq. 10.4,
/// k_blend = 1 − δ), gravity and the quadratic/linear air drag of eq. 10.5, friction and
/// restitution on contact.
///
/// \code
/// tbsp::PbdClothSimulator sim;
/// sim.setMesh(template.V, template.F);          // rest shape: rest lengths, angles, masses
/// sim.setClothness(delta);                      // δ = 0: skinned (kinematic), 1: simulated
/// sim.reset(skinned_frame0);
/// for (frame ...) sim.step(skinned(frame), posed_proxies(proxies, T(frame)));
/// \endcode
///
/// Units: positions in metres and time in seconds for the defaults (gravity 9.81, drag h = 0.005).
/// Deterministic: constraints are projected colour by colour (greedy graph colouring: no two
/// constraints of a colour share a vertex), each colour in parallel (OpenMP), so the result is
/// bit-identical for any thread count.

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "tbsp/cloth/collision_proxies.h"

namespace tbsp {

/// \brief Material of one cloth region, ρ = (d_n, d_t, k_bend) of thesis §10.5.
struct ClothMaterial {
  double d_n = 2.0;     ///< normal drag coefficient, [0, 10] in the thesis' search (eq. 10.5)
  double d_t = 4.0;     ///< tangential drag coefficient, [0, 50] (eq. 10.5)
  double k_bend = 0.3;  ///< bending stiffness in [0, 1] (eq. 10.3)
};

/// \brief Simulation settings shared by all regions (fixed during parameter estimation, §10.5).
struct PbdSettings {
  /// Constraint sweeps per sub-step, 1..1000. The thesis' n_iter = 16 sweeps per frame are spent
  /// by default as 16 sub-steps of 1 sweep (Macklin et al. 2019, "small steps"): the same
  /// constraint work, but a hanging 25×25 cloth stretches 2.8 % instead of 41 % (docs/dev/cloth_experiments.md).
  int iterations = 1;
  int substeps = 16;             ///< sub-steps per frame, 1..64 (iterations × substeps = n_iter)
  double time_step = 1.0 / 40;   ///< seconds per frame (thesis: the 40 fps capture rate), > 0
  Eigen::Vector3d gravity{0, -9.81, 0};  ///< m/s²
  double drag_constant = 0.005;  ///< h of eq. 10.5
  /// Length unit, in metres, that the quadratic normal drag d_n |u_n|² refers to: 0.01 means
  /// velocities in cm/s, which makes the thesis' range d_n ∈ [0, 10] matter against gravity
  /// (in m/s its effect would be 100× weaker; the thesis does not state its unit, this is our
  /// reading). The linear tangential term does not depend on it. > 0.
  double drag_unit = 0.01;
  double k_stretch = 1.0;        ///< stretch stiffness in [0, 1] (thesis: fixed 1)
  double thickness = 0.005;      ///< collision distance to proxies and between cloth vertices, metres, ≥ 0
  /// Coulomb friction coefficient against proxies, applied to positions (Macklin et al. 2014):
  /// a tangential slide shorter than friction × penetration depth is undone (static), a longer
  /// one shortened by that amount (kinetic). [0, 2], default 0.5.
  double friction = 0.5;
  double restitution = 0.0;      ///< share of the normal velocity into a proxy that is reflected, [0, 1]
  bool self_collision = true;    ///< vertex–vertex self-collision via a spatial hash
  /// Self-collision and proxy candidates are searched every this many sub-steps (within the
  /// distance a vertex can travel meanwhile), 1..64. Default 4.
  int contact_interval = 4;
  /// Long-range attachments (Kim et al. 2012): each vertex with δ > 0.5 stays within its geodesic
  /// rest distance (along edges, × (1 + tether_slack)) of the nearest mostly-skinned (δ ≤ 0.5) vertex.
  /// Not in the thesis; bounds the stretch of long hanging cloth (a skirt from the waist) that
  /// 16 sweeps alone cannot hold (docs/dev/cloth_experiments.md). Default true.
  bool tethers = true;
  double tether_slack = 0.02;    ///< [0, 1]
  /// Rest dihedral angle of the bending constraints: false (default) = the template's own angle,
  /// so a curved skirt keeps its shape; true = φ = 0 everywhere as in the thesis.
  bool flat_rest_angle = false;
};

/// \brief Checks the ranges stated above. \throws InvalidInput naming `where` and the first
/// setting out of range.
void validate_pbd_settings(const PbdSettings& s, const char* where = "tbsp::PbdSettings");

/// \brief The PBD cloth solver. Not thread-safe per object; independent objects run in
/// parallel (parameter estimation simulates many samples at once).
class PbdClothSimulator {
public:
  /// \brief Sets the rest shape: builds stretch constraints (one per edge), bending constraints
  /// (one per interior edge), area masses (⅓ of the adjacent triangle areas) and the colouring.
  /// Resets clothness to 1 everywhere, regions to 0, state to the rest shape.
  /// \throws InvalidInput for an empty mesh, bad indices, non-finite coordinates.
  void setMesh(const Eigen::MatrixX3d& V_rest, const Eigen::MatrixX3i& F);
  /// \brief Per-vertex clothness δ ∈ [0,1] (ClothSegmentation). δ = 0 vertices follow the
  /// targets exactly (kinematic); others are simulated with a blend constraint of stiffness 1 − δ.
  void setClothness(const Eigen::VectorXd& delta);
  /// \brief Per-vertex region label (0..k−1) choosing the material; default all 0.
  void setRegions(const Eigen::VectorXi& region);
  /// Material of region r (extends the table as needed). \throws InvalidInput for values outside
  /// finite d_n, d_t ≥ 0 and k_bend ∈ [0, 1].
  void setMaterial(const ClothMaterial& m, int region = 0);
  /// Settings; takes effect at the next step(). \throws InvalidInput for values out of range.
  void setSettings(const PbdSettings& s);

  /// \brief Positions = P, velocities = 0. \throws InvalidInput on a size mismatch / NaN.
  void reset(const Eigen::MatrixX3d& P);
  /// \brief The state after a step(targets, proxies) that ended at positions P with velocities U
  /// (m/s; zero for kinematic vertices): restarting from a known state (the parameter estimation
  /// restarts from the reference sequence). \throws InvalidInput on a size mismatch / NaN.
  void reset(const Eigen::MatrixX3d& P, const Eigen::MatrixX3d& U, const Eigen::MatrixX3d& targets, const std::vector<RoundCone>& proxies);
  /// \brief Advances one frame. `targets` are the skinned positions of this frame (blend
  /// constraints and kinematic vertices; empty = keep the current positions of kinematic
  /// vertices and no blend), `proxies` the collision cones in this frame's pose (their previous
  /// frame's poses give the surface velocity for friction).
  /// \throws InvalidInput on a size mismatch or non-finite targets; NumericalFailure when the
  /// frame ends with non-finite positions or velocities (an explicit step diverged: drag far
  /// beyond the thesis' ranges, or too long a time step), instead of handing them out.
  void step(const Eigen::MatrixX3d& targets, const std::vector<RoundCone>& proxies = {});

  const Eigen::MatrixX3d& positions() const { return x_; }
  const Eigen::MatrixX3d& velocities() const { return u_; }
  const Eigen::VectorXd& masses() const { return mass_; }
  const PbdSettings& settings() const { return settings_; }
  int numStretchConstraints() const { return int(stretch_.size()); }
  int numBendConstraints() const { return int(bend_.size()); }
  /// Colours of the stretch / bending constraint graphs (parallel sweeps per iteration).
  int numColours() const { return int(stretch_colours_.size() + bend_colours_.size()); }

  /// Kinetic energy ½ Σ m |u|² of the simulated vertices.
  double kineticEnergy() const;
  /// Gravitational potential −Σ m g·x of the simulated vertices.
  double potentialEnergy() const;
  /// Largest relative edge strain |l / l₀ − 1| over the simulated edges (both ends δ > 0; the
  /// skinned part deforms as the skinning says).
  double maxStrain() const;
  /// The q-quantile (0..1) of the strains of the simulated edges (0.99: all but the worst 1 %).
  double strainQuantile(double q) const;
  /// Vertex pairs in self-contact at the last step and vertex–proxy contacts.
  int numSelfContacts() const { return self_contacts_; }
  int numProxyContacts() const { return proxy_contacts_; }

private:
  struct Stretch { int a, b; double rest; };
  struct Bend { int a, b, c, d; double rest; int region; };  // edge (a,b), wings c and d
  using Points = std::vector<Eigen::Vector3d>;
  void buildColours();
  void substep(const Eigen::MatrixX3d& targets, const std::vector<RoundCone>& prev, const std::vector<RoundCone>& cur,
               double t1, double dt);
  void applyExternal(double dt);
  void findProxyCandidates(const std::vector<RoundCone>& proxies, const std::vector<RoundCone>& next, double reach);
  void findSelfContacts(const std::vector<double>& travel);
  void projectStretch(double k);
  void buildTethers();
  void projectTethers();
  void projectBend(const std::vector<double>& k_per_region);
  void projectBlend(const Points& targets, const std::vector<double>& k_blend);
  void projectProxies(const std::vector<RoundCone>& prev, const std::vector<RoundCone>& cur);
  void projectSelf();
  void contactVelocities(const std::vector<RoundCone>& prev, const std::vector<RoundCone>& cur, double dt);
  void syncOut();

  // Per-vertex and per-constraint loops run on several threads only for meshes large enough
  // to pay for the barriers.
  static constexpr std::size_t kParallelMin = 1024;

  PbdSettings settings_;
  Eigen::MatrixX3i F_;
  Eigen::MatrixX3d rest_;
  Eigen::MatrixX3d x_, u_;        // public copies of the state
  Points pos_, vel_, pred_;       // working state (contiguous per vertex)
  Eigen::MatrixX3d targets_prev_;
  Eigen::VectorXd mass_, delta_;
  std::vector<double> inv_mass_;
  Points sub_targets_;            // scratch: the targets at the end of a sub-step
  Points face_normal_;            // scratch: area-weighted face normals of a sub-step
  std::vector<int> vf_offsets_, vf_faces_;  // vertex i's faces, ascending: [vf_offsets_[i], vf_offsets_[i+1])
  std::vector<double> travel_;    // scratch: distance each vertex can travel in a contact window
  std::vector<double> k_blend_;  // per-sweep blend stiffness, cached
  int k_blend_sweeps_ = 0;
  Eigen::VectorXi region_;
  std::vector<ClothMaterial> materials_{ClothMaterial{}};
  std::vector<Stretch> stretch_;
  std::vector<Bend> bend_;
  std::vector<std::vector<int>> stretch_colours_, bend_colours_;
  std::size_t stretch_conflict_colour_ = std::size_t(-1), bend_conflict_colour_ = std::size_t(-1);  // swept by one thread
  std::vector<int> tether_anchor_;     // nearest kinematic vertex (-1: none)
  std::vector<double> tether_length_;  // its geodesic rest distance × (1 + slack)
  bool tethers_dirty_ = true;
  std::vector<std::pair<int, int>> self_pairs_;
  std::vector<std::pair<int, int>> proxy_pairs_;  // (vertex, proxy) candidates, sorted by vertex
  std::vector<int> proxy_offsets_;                // vertex v's candidates: [offsets[v], offsets[v+1])
  std::vector<RoundCone> proxies_prev_;
  int self_contacts_ = 0, proxy_contacts_ = 0;
};

}  // namespace tbsp
