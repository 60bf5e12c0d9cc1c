// Segmentation on real captured frames (issue 26): the Vlasic samba dancer (a dress, four frames
// of a multi-view capture with shared connectivity, ../shared/data). No per-vertex labels exist;
// the skirt is the band of the body between 28 % and 42 % of its height (every vertex there is
// on the skirt: the legs inside it are not part of the captured surface), the head the top 10 %,
// the lower legs and feet the bottom 20 % (docs/images/cloth_samba_segmentation.png).
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "test_util.h"
#include "tbsp/cloth/cloth_segmentation.h"
#include "tbsp/io/mesh_io.h"

using namespace tbsp;

TEST(ClothSegmentationReal, SambaSkirtIsClothHeadAndLegsAreBody) {
  const std::string dir = std::string(TBSP_SHARED_DATA_DIR) + "/meshes/CraGL__Hyperspectral-Inverse-Skinning/models/samba/";
  TBSP_REQUIRE_FILE(dir + "mesh_0000.obj");
  ClothSegmentation seg;
  TriMesh first;
  for (const char* f : {"mesh_0000.obj", "mesh_0050.obj", "mesh_0100.obj", "mesh_0150.obj"}) {
    const TriMesh m = read_mesh(dir + f);
    if (first.V.rows() == 0) {
      first = m;
      seg.begin(m.V, m.F);
    } else {
      seg.addFrame(m.V);
    }
  }
  const ClothSegmentation::Result r = seg.finish();
  const double lo = first.V.col(1).minCoeff(), hi = first.V.col(1).maxCoeff();
  auto share = [&](double a, double b) {  // share of the vertices in the height band [a, b) with δ > 0.5
    int n = 0, cloth = 0;
    for (Eigen::Index i = 0; i < first.V.rows(); ++i) {
      const double h = (first.V(i, 1) - lo) / (hi - lo);
      if (h >= a && h < b) ++n, cloth += r.clothness(i) > 0.5;
    }
    return n ? double(cloth) / n : 0.0;
  };
  const double skirt = share(0.28, 0.42), head = share(0.9, 1.01), legs = share(0.0, 0.2);
  std::printf("samba: skirt band %.3f cloth, head %.3f, lower legs %.3f\n", skirt, head, legs);
  EXPECT_GE(skirt, 0.95);
  EXPECT_LE(head, 0.05);
  EXPECT_LE(legs, 0.05);
}
