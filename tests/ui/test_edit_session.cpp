// The editing session of tbsp-studio without UI (label unit): documents, undo, replay.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <fstream>

#include "edit_session.h"
#include "tbsp/core/error.h"
#include "tbsp/io/mesh_io.h"
#include "test_util.h"

using tbsp::test::sample;
using tbsp::test::temp_dir;

TEST(EditSession, BestRigidMotionRecoversAKnownMotion) {
  Eigen::MatrixX3d a(5, 3);
  a << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d t(0.3, -0.2, 0.5);
  const Eigen::MatrixX3d b = (a * R.transpose()).rowwise() + t.transpose();
  const tbsp::RigidMotion m = tbsp::studio::best_rigid_motion(a, b);
  for (Eigen::Index i = 0; i < a.rows(); ++i)
    EXPECT_LT((m.apply(a.row(i).transpose()) - b.row(i).transpose()).norm(), 1e-12);
}

TEST(EditSession, DocumentsUndoRedoAndWarmIterationsConvergeToTheReplay) {
  tbsp::studio::EditSession s;
  EXPECT_THROW(s.addHandle({{"vertices", {0}}}), tbsp::InvalidInput) << "no mesh open";
  s.open(sample("bumpy_bar.off"), 0);
  const Eigen::Index n = s.setup().surface.V.rows();
  EXPECT_THROW(s.addHandle({{"vertices", {0, int(n)}}}), tbsp::InvalidInput);
  EXPECT_THROW(s.addHandle({{"sphere", {{"center", {9, 9, 9}}, {"radius", 0.01}}}}), tbsp::InvalidInput);
  EXPECT_EQ(s.numHandles(), 0) << "refused edits change nothing";
  ASSERT_NO_THROW(s.addHandle({{"box", {{"min", {-1, -1, -1}}, {"max", {0.05, 1, 1}}}}})) << "b1";
  ASSERT_NO_THROW(s.addHandle({{"box", {{"min", {0.95, -1, -1}}, {"max", {2, 1, 1}}}}})) << "b2";
  s.setHandleMotion(1, {0, 0.3, 0});
  s.setHandleMotion(1, {0, 0.4, 0}, Eigen::Vector3d::UnitZ(), 0, Eigen::Vector3d::Zero(), /*undoable=*/false);
  EXPECT_NEAR(s.handleMotion(1).translation.y(), 0.4, 1e-15);
  // warm-started iterations (what the view shows) approach the replay from rest (what is saved)
  s.requestIterations(400);
  s.waitIdle();
  const tbsp::TriMesh replay = s.replay(400);
  EXPECT_LT((s.currentSurface() - replay.V).cwiseAbs().maxCoeff(), 2e-3 * tbsp::bbox_diagonal(replay.V));
  EXPECT_GT((replay.V - s.setup().surface.V).rowwise().norm().maxCoeff(), 0.35);
  // the drag was one undo step (the second move merged into it)
  ASSERT_TRUE(s.undo());
  EXPECT_NEAR(s.handleMotion(1).translation.norm(), 0.0, 1e-15);
  ASSERT_TRUE(s.redo());
  EXPECT_NEAR(s.handleMotion(1).translation.y(), 0.4, 1e-15);
  ASSERT_TRUE(s.undo());
  ASSERT_TRUE(s.undo());
  ASSERT_TRUE(s.undo());
  EXPECT_EQ(s.numHandles(), 0);
  EXPECT_FALSE(s.undo());
  // saving without handles is refused; a failed save leaves nothing
  const auto dir = temp_dir("edit_session");
  EXPECT_THROW(s.save((dir / "m.ply").string(), (dir / "h.json").string(), "", "", 10), tbsp::InvalidInput);
  EXPECT_FALSE(std::filesystem::exists(dir / "m.ply"));
  // a saved handles file loads back into a session (what the CLI reads, the app reads too)
  {
    s.redo();
    s.redo();
    s.redo();
    s.save((dir / "m.ply").string(), (dir / "h.json").string(), "", "", 60);
    tbsp::studio::EditSession again;
    again.open(sample("bumpy_bar.off"), 0);
    again.loadHandles((dir / "h.json").string());
    EXPECT_EQ(again.numHandles(), 2);
    EXPECT_LT((again.replay(60).V - tbsp::read_mesh((dir / "m.ply").string()).V).cwiseAbs().maxCoeff(), 1e-12);
    std::ofstream(dir / "bad.json") << R"({"handles": [{"vertices": [3, 100000]}]})";
    try {
      again.loadHandles((dir / "bad.json").string());
      ADD_FAILURE() << "expected FileError";
    } catch (const tbsp::InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("bad.json: handles[0].vertices[1]"), std::string::npos) << e.what();
    }
    EXPECT_EQ(again.numHandles(), 2) << "a refused file changes nothing";
    s.undo();
    s.undo();
    s.undo();
  }
  // a handle added to a deformed shape holds it where it is
  s.redo();
  s.redo();
  s.redo();
  s.requestIterations(400);
  s.waitIdle();
  const Eigen::MatrixX3d before = s.currentSurface();
  s.addHandle({{"sphere", {{"center", {0.5, 0.1, 0}}, {"radius", 0.05}}}});
  s.requestIterations(50);
  s.waitIdle();
  EXPECT_LT((s.currentSurface() - before).cwiseAbs().maxCoeff(), 0.02) << "adding a handle does not snap the shape";
}

TEST(EditSession, SurfaceSolverFollowsDragsAndEqualsItsReplay) {
  tbsp::studio::EditSession s;
  s.open(sample("bumpy_bar.off"), 0, tbsp::studio::EditSolver::Surface);
  EXPECT_EQ(s.setup().tets.T.rows(), 0) << "no tet mesh for surface editing";
  s.addHandle({{"box", {{"min", {-1, -1, -1}}, {"max", {0.05, 1, 1}}}}});
  s.addHandle({{"box", {{"min", {0.95, -1, -1}}, {"max", {2, 1, 1}}}}});
  EXPECT_THROW(s.addRigid({{"box", {{"min", {0.4, -1, -1}}, {"max", {0.6, 1, 1}}}}}), tbsp::InvalidInput);
  s.requestIterations(1);
  s.waitIdle();
  for (bool field : {false, true}) {
    s.setRotationField(field);
    for (double dy : {0.2, 0.4}) {  // the second drag re-solves with the kept factorization
      s.setHandleMotion(1, {0, dy, 0}, Eigen::Vector3d::UnitZ(), 30, Eigen::Vector3d(1, 0, 0));
      s.requestIterations(1);
      s.waitIdle();
      const tbsp::TriMesh r = s.replay(1);
      EXPECT_LT((s.currentSurface() - r.V).cwiseAbs().maxCoeff(), 1e-9) << "field " << field << " dy " << dy;
      EXPECT_GT((r.V - s.setup().surface.V).rowwise().norm().maxCoeff(), dy * 0.9);
    }
  }
  const nlohmann::json c = s.constraintsDoc();
  EXPECT_EQ(c["rotation_field"], true);
  EXPECT_EQ(c["constraints"].size(), 2u);
}

TEST(EditSession, ReopeningNeverReusesTheSolverOfThePreviousMesh) {
  tbsp::studio::EditSession s;
  const nlohmann::json fixed = {{"box", {{"min", {-1, -1, -1}}, {"max", {0.05, 1, 1}}}}};
  const nlohmann::json moved = {{"box", {{"min", {0.95, -1, -1}}, {"max", {2, 1, 1}}}}};
  for (long tets : {0L, 3000L}) {  // same regions, another tet mesh: the structure key alone would match
    s.open(sample("bumpy_bar.off"), tets);
    s.addHandle(fixed);
    s.addHandle(moved);
    s.setHandleMotion(1, {0, 0.3, 0});
    s.requestIterations(300);
    s.waitIdle();
    const tbsp::TriMesh r = s.replay(300);
    ASSERT_EQ(s.currentSurface().rows(), r.V.rows());
    EXPECT_LT((s.currentSurface() - r.V).cwiseAbs().maxCoeff(), 5e-3) << "tets " << tets;
  }
}
