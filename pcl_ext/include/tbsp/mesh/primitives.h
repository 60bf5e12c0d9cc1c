#pragma once
/// \file primitives.h
/// \brief Procedural meshes for tests, benchmarks and the sample data (all closed meshes are
/// consistently oriented with outward normals).

#include "tbsp/mesh/tri_mesh.h"

namespace tbsp {

/// Icosphere of radius r: 12 vertices at level 0, 10·4^level + 2 vertices after `level`
/// 1-to-4 subdivisions, all vertices exactly on the sphere.
TriMesh make_icosphere(int level, double radius = 1.0);

/// Planar (nx+1) by (ny+1) vertex grid on [0,sx]×[0,sy] at z=0; `jitter` moves interior
/// vertices randomly by up to that fraction of a cell per axis (seeded, deterministic).
/// jitter < 1/6 keeps every triangle positively oriented (det >= 1 - 6·jitter); larger values
/// can flip triangles.
TriMesh make_grid(int nx, int ny, double sx = 1.0, double sy = 1.0, double jitter = 0.0, unsigned seed = 1);

/// Closed capped tube along +x from 0 to `length`: `rings` rings of `segments` vertices with
/// radius r, plus two cap centre vertices. Ring i lies at x = length·i/(rings−1).
TriMesh make_tube(int rings, int segments, double length = 1.0, double radius = 0.1);

/// \brief Closed box surface [0,sx]×[0,sy]×[0,sz] with nx × ny × nz quads per side direction
/// (each split into two triangles), outward oriented, manifold, genus 0 — e.g. the bar of
/// thesis Fig. 7.2/7.3 before tetrahedralization. \throws InvalidInput for n < 1 or size ≤ 0.
TriMesh make_box(int nx, int ny, int nz, double sx = 1.0, double sy = 1.0, double sz = 1.0);

}  // namespace tbsp
