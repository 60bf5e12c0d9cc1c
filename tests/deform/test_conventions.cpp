// docs/conventions.md: every main class validates its options where they are set, reports
// progress, can be cancelled (tbsp::Cancelled), stays usable after a cancel, and has Ptr types.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <tuple>
#include <type_traits>

#include <pcl/point_types.h>

#include "deform/tet_test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/deform/deformation_transfer.h"
#include "tbsp/deform/laplacian_deformer.h"
#include "tbsp/deform/tet_deformer.h"
#include "tbsp/fitting/inverse_texture_mapping.h"
#include "tbsp/fitting/template_fitting.h"
#include "tbsp/mesh/heat_geodesics.h"
#include "tbsp/mesh/primitives.h"
#include "tbsp/mesh/tetrahedralize.h"

using namespace tbsp;

namespace {
// A progress callback that cancels at its n-th call (n = 1: the first); counts the calls.
struct CancelAt {
  int n, calls = 0;
  ProgressCallback cb() {
    return [this](double, const std::string&) { return ++calls < n; };
  }
};

template <class F>
std::string invalid_message(F&& f) {
  try {
    f();
  } catch (const InvalidInput& e) {
    return e.what();
  }
  return "";
}
}  // namespace

static_assert(std::is_same_v<LaplacianDeformer::Ptr, std::shared_ptr<LaplacianDeformer>>);
static_assert(std::is_same_v<TetDeformer::ConstPtr, std::shared_ptr<const TetDeformer>>);
static_assert(std::is_same_v<InverseTextureMapping::Ptr, std::shared_ptr<InverseTextureMapping>>);
static_assert(std::is_same_v<DeformationTransfer::Ptr, std::shared_ptr<DeformationTransfer>>);
static_assert(std::is_same_v<TemplateFitting<pcl::PointXYZ>::Ptr, std::shared_ptr<TemplateFitting<pcl::PointXYZ>>>);

TEST(Conventions, SetOptionsRejectsInvalidValuesAndNamesTheClass) {
  LaplacianDeformerOptions lo;
  lo.scale = -1;
  EXPECT_FALSE(lo.isValid());
  LaplacianDeformer ld;
  EXPECT_NE(invalid_message([&] { ld.setOptions(lo); }).find("[tbsp::LaplacianDeformer::setOptions] scale"), std::string::npos);
  EXPECT_DOUBLE_EQ(ld.options().scale, 1.0);  // unchanged

  TetDeformerOptions to;
  to.max_handle_step_deg = 0;  // was clamped to 1e-3 silently before
  TetDeformer td;
  EXPECT_NE(invalid_message([&] { td.setOptions(to); }).find("[tbsp::TetDeformer::setOptions] max_handle_step_deg"),
            std::string::npos);
  to.max_handle_step_deg = 200;
  EXPECT_FALSE(to.isValid());

  DeformationTransferOptions dto;
  dto.radius = -0.1;
  DeformationTransfer dt;
  EXPECT_NE(invalid_message([&] { dt.setOptions(dto); }).find("[tbsp::DeformationTransfer::setOptions] radius"),
            std::string::npos);

  InverseTextureMappingOptions io;
  io.sigma = -1;
  InverseTextureMapping itm;
  EXPECT_NE(invalid_message([&] { itm.setOptions(io); }).find("[tbsp::InverseTextureMapping::setOptions]"), std::string::npos);

  FitParameters fp;
  fp.max_normal_angle_deg = -5;
  TemplateFitting<pcl::PointXYZ> tf;
  EXPECT_FALSE(invalid_message([&] { tf.setOptions(fp); }).empty());

  HeatGeodesicsOptions ho;
  ho.time_factor = 0;
  const TriMesh s = make_icosphere(1);
  EXPECT_NE(invalid_message([&] { HeatGeodesics h(s.V, s.F, ho); }).find("[tbsp::HeatGeodesics]"), std::string::npos);
}

TEST(Conventions, CancellationLeavesEveryClassUsable) {
  // LaplacianDeformer
  {
    const TriMesh m = make_icosphere(2);
    LaplacianDeformer d;
    d.setMesh(m);
    for (int v : {0, 5, 9, 30}) d.addPositionConstraint(SurfacePoint::atVertex(v), m.V.row(v).transpose() * 1.1);
    CancelAt c{1};
    d.setProgressCallback(c.cb());
    EXPECT_THROW(d.deform(), Cancelled);
    d.setProgressCallback({});
    EXPECT_EQ(d.deform().rows(), m.V.rows());
  }
  // TetDeformer
  {
    const TetMesh tets = test::make_bar_tets(1.0, 0.2, 6, 2);
    TetDeformer d;
    d.setMesh(tets);
    d.addRegionHandle(test::vertices_x(tets.V, 0.01, false), {});
    d.addRegionHandle(test::vertices_x(tets.V, 0.99, true), RigidMotion{});
    CancelAt c{1};
    d.setProgressCallback(c.cb());
    EXPECT_THROW(d.deform(5), Cancelled);
    d.setProgressCallback({});
    EXPECT_EQ(d.deform(5).rows(), tets.V.rows());
  }
  // DeformationTransfer: a cancelled precompute keeps the previous B
  {
    const TetMesh tets = test::make_bar_tets(1.0, 0.2, 6, 2);
    DeformationTransfer dt;
    dt.precompute(tets, tets.V);
    const Eigen::Index before = dt.matrix().nonZeros();
    CancelAt c{1};
    dt.setProgressCallback(c.cb());
    EXPECT_THROW(dt.precompute(tets, tets.V.topRows(10)), Cancelled);
    EXPECT_EQ(dt.matrix().nonZeros(), before);
    EXPECT_EQ(dt.report().vertices, tets.V.rows());
  }
  // InverseTextureMapping
  {
    const TriMesh m = make_grid(10, 10);
    std::vector<TextureConstraint> cons;
    for (auto [x, y, v] : {std::tuple{5.0, 5.0, 0}, {60.0, 5.0, 10}, {5.0, 60.0, 110}, {60.0, 60.0, 120}}) {
      TextureConstraint t;
      t.pixel = {x, y};
      t.vertex = v;
      cons.push_back(t);
    }
    InverseTextureMapping itm;
    itm.setInputMesh(m);
    itm.setImageSize(64, 64);
    itm.setConstraints(cons);
    CancelAt c{2};
    itm.setProgressCallback(c.cb());
    EXPECT_THROW(itm.compute(), Cancelled);
    itm.setProgressCallback({});
    const TextureMappingResult r = itm.compute();
    EXPECT_EQ(itm.report().constraints, 4);
    EXPECT_EQ(r.report.constraints, 4);
  }
  // TemplateFitting
  {
    const TriMesh templ = make_icosphere(2);
    pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
    const TriMesh dense = make_icosphere(4);
    for (Eigen::Index i = 0; i < dense.V.rows(); ++i)
      cloud->push_back(pcl::PointXYZ(float(1.2 * dense.V(i, 0)), float(dense.V(i, 1)), float(dense.V(i, 2))));
    std::vector<FitMarker> markers;
    for (int v : {0, 1, 2, 3, 4, 5}) {
      // the dense sphere's vertex nearest to the template vertex, stretched like the cloud
      Eigen::Index k;
      (dense.V.rowwise() - templ.V.row(v)).rowwise().squaredNorm().minCoeff(&k);
      markers.emplace_back(v, k);
    }
    TemplateFitting<pcl::PointXYZ> fit;
    fit.setInputCloud(cloud);
    fit.setInputTemplate(templ);
    fit.setMarkers(markers);
    CancelAt c{3};
    fit.setProgressCallback(c.cb());
    TriMesh out;
    EXPECT_THROW(fit.reconstruct(out), Cancelled);
    EXPECT_EQ(out.V.rows(), 0);  // untouched
    fit.setProgressCallback({});
    const FitReport r = fit.reconstruct(out);
    EXPECT_EQ(out.V.rows(), templ.V.rows());
    EXPECT_EQ(fit.report().iterations, r.iterations);
  }
  // HeatGeodesics, decimate_mesh, tetrahedralize
  {
    const TriMesh s = make_icosphere(3);
    HeatGeodesicsOptions ho;
    CancelAt c{1};
    ho.progress = c.cb();
    EXPECT_THROW(HeatGeodesics(s.V, s.F, ho), Cancelled);
    CancelAt c2{3};
    EXPECT_THROW(decimate_mesh(s, 100, c2.cb()), Cancelled);
    EXPECT_GE(c2.calls, 3);  // reported progress while collapsing
    EXPECT_LE(decimate_mesh(s, 100).F.rows(), 100);
    TetgenOptions to;
    CancelAt c3{1};
    to.progress = c3.cb();
    EXPECT_THROW(tetrahedralize(make_box(4, 2, 2, 1.0, 0.5, 0.5), to), Cancelled);
  }
}
