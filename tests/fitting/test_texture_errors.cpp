// InverseTextureMapping: bad input gives clear errors (no real data needed).
#include <gtest/gtest.h>

#include "tbsp/core/error.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/mesh/primitives.h"

using namespace tbsp;

namespace {
std::string error_of(const TriMesh& m, int W, int H, const std::vector<TextureConstraint>& c, const std::vector<std::uint8_t>& mask = {}) {
  InverseTextureMapping itm;
  itm.setInputMesh(m);
  itm.setImageSize(W, H);
  itm.setMask(mask);
  itm.setConstraints(c);
  try {
    itm.compute();
  } catch (const InvalidInput& e) {
    return e.what();
  }
  return "";
}
TextureConstraint at(double x, double y, int v) {
  TextureConstraint c;
  c.pixel = {x, y};
  c.vertex = v;
  return c;
}
}  // namespace

TEST(TextureErrors, BadInputGivesClearErrors) {
  const TriMesh m = make_grid(10, 10);  // 121 vertices, a flat disc-like sheet
  const std::vector<TextureConstraint> good{at(5, 5, 0), at(60, 5, 10), at(5, 60, 110), at(60, 60, 120)};
  EXPECT_EQ(error_of(m, 64, 64, good), "");
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1]}).find("at least 3"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], at(70, 3, 5)}).find("outside the 64x64 image"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], at(-1, 3, 5)}).find("constraint 2"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], at(30, 30, 500)}).find("vertex 500 does not exist"), std::string::npos);
  TextureConstraint noidx;
  noidx.pixel = {30, 30};
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], noidx}).find("face -1 does not exist"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], at(5, 5, 7)}).find("same pixel"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {at(5, 5, 0), at(20, 5, 1), at(40, 5, 2)}).find("on one line"), std::string::npos);
  // one mesh point given two pixels (found by hand 2026-12-06: three pixels on vertex 0 were
  // accepted, exit 0, 0.07 % of the vertices matched), also as a face point on that vertex
  EXPECT_NE(error_of(m, 64, 64, {good[0], good[1], at(30, 30, 0)}).find("the same mesh point as constraint 0"), std::string::npos);
  TextureConstraint on_vertex;
  on_vertex.pixel = {30, 30};
  on_vertex.face = 0;
  on_vertex.barycentric = Eigen::Vector3d::Zero();
  on_vertex.barycentric(0) = 1;  // the face's first corner
  const int corner = m.F(0, 0);
  EXPECT_NE(error_of(m, 64, 64, {at(5, 5, corner), good[1], on_vertex}).find("the same mesh point as constraint 0"), std::string::npos);
  EXPECT_NE(error_of(m, 1, 64, good).find("too small"), std::string::npos);
  // Masks: wrong size, a constraint outside, a piece without constraints.
  EXPECT_NE(error_of(m, 64, 64, good, std::vector<std::uint8_t>(10, 1)).find("mask has 10 entries"), std::string::npos);
  std::vector<std::uint8_t> mask(64 * 64, 0);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) mask[y * 64 + x] = (x < 40 || x > 50) ? 1 : 0;  // two pieces
  EXPECT_NE(error_of(m, 64, 64, {at(5, 5, 0), at(30, 5, 10), at(5, 60, 110)}, mask).find("has 0 constraint"), std::string::npos);
  EXPECT_NE(error_of(m, 64, 64, {at(45, 5, 0), at(30, 5, 10), at(5, 60, 110)}, mask).find("outside the mask"), std::string::npos);
  // Non-manifold mesh: three triangles on one edge.
  TriMesh nm;
  nm.V.resize(5, 3);
  nm.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1;
  nm.F.resize(3, 3);
  nm.F << 0, 1, 2, 1, 0, 3, 0, 1, 4;
  EXPECT_NE(error_of(nm, 64, 64, {at(5, 5, 0), at(60, 5, 1), at(5, 60, 2)}).find("non-manifold"), std::string::npos);
  // Options: rejected where they are set (the convention of every class, docs/conventions.md)
  InverseTextureMappingOptions bad_options;
  bad_options.omega = 0;
  InverseTextureMapping bad;
  EXPECT_THROW(bad.setOptions(bad_options), InvalidInput);
  EXPECT_THROW(InverseTextureMapping{bad_options}, InvalidInput);
  EXPECT_GT(bad.options().omega, 0.0);  // unchanged by the rejected call
  bad_options.omega = 1e-6;  // loses the constraints (34 px residuals on the sample bar)
  EXPECT_THROW(bad.setOptions(bad_options), InvalidInput);
  // a draping offset beyond the mesh's size (1e300 ended in a heat-geodesics message)
  InverseTextureMappingOptions far;
  far.normal_offset = 1e300;
  InverseTextureMapping itm(far);
  itm.setInputMesh(m);
  itm.setImageSize(64, 64);
  itm.setConstraints(good);
  try {
    itm.compute();
    ADD_FAILURE() << "an offset of 1e300 was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("normal_offset = "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("beyond the mesh's size"), std::string::npos) << e.what();
  }
}
