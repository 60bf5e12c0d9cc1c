#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/camera_io.h"

using namespace tbsp;

namespace {
std::vector<Camera> some_cameras(bool distortion) {
  std::vector<Camera> cams;
  for (int i = 0; i < 4; ++i) {
    const double a = i * M_PI / 2;
    Camera c = Camera::lookAt("view" + std::to_string(i) + ".png", 640, 480, 0.9, {3 * std::cos(a), 1.0, 3 * std::sin(a)}, {0, 0, 0}, {0, 1, 0});
    Distortion d;
    if (distortion) { d.k1 = -0.1 * i; d.k2 = 0.01; d.p1 = 1e-4; d.p2 = -2e-4; }
    cams.emplace_back(c.name(), 640, 480, c.K(), c.R(), c.t(), d);
  }
  return cams;
}
void expect_same_projection(const Camera& a, const Camera& b) {
  for (const Eigen::Vector3d& X : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.3, -0.2, 0.1), Eigen::Vector3d(-0.4, 0.5, 0.2)})
    EXPECT_LT((a.project(X) - b.project(X)).norm(), 1e-6) << a.name();
}
}  // namespace

TEST(CameraIo, MiddleburyRoundTrip) {
  const auto dir = test::temp_dir("mb");
  const auto cams = some_cameras(false);
  write_middlebury_par((dir / "x_par.txt").string(), cams);
  const auto back = read_middlebury_par((dir / "x_par.txt").string(), 640, 480);
  ASSERT_EQ(back.size(), cams.size());
  for (std::size_t i = 0; i < cams.size(); ++i) {
    EXPECT_EQ(back[i].name(), cams[i].name());
    expect_same_projection(cams[i], back[i]);
  }
  EXPECT_THROW(write_middlebury_par((dir / "d_par.txt").string(), some_cameras(true)), InvalidInput);
}

TEST(CameraIo, ColmapRoundTripWithDistortionAndPixelConvention) {
  const auto dir = test::temp_dir("colmap");
  const auto cams = some_cameras(true);
  write_colmap_text(dir.string(), cams);
  const auto back = read_colmap_text(dir.string());
  ASSERT_EQ(back.size(), cams.size());
  for (std::size_t i = 0; i < cams.size(); ++i) expect_same_projection(cams[i], back[i]);
  // A hand-written COLMAP model: the principal point (320, 240) in COLMAP's convention (pixel
  // centres at +0.5) is (319.5, 239.5) in tbsp's.
  test::write_text(dir / "cameras.txt", "# c\n1 SIMPLE_PINHOLE 640 480 500 320 240\n2 RADIAL 640 480 500 320 240 0.1 0.01\n");
  test::write_text(dir / "images.txt", "# i\n1 1 0 0 0 0 0 2 1 a.png\n10 20 0.5 -1 1 5 1\n2 1 0 0 0 0 0 2 2 b.png\n\n");
  const auto hand = read_colmap_text(dir.string());
  ASSERT_EQ(hand.size(), 2u);
  EXPECT_EQ(hand[0].name(), "a.png");
  EXPECT_NEAR(hand[0].project({0, 0, 0}).x(), 319.5, 1e-12);
  EXPECT_NEAR(hand[1].distortion().k2, 0.01, 1e-15);
}

TEST(CameraIo, ProjectionMatrixFormats) {
  const auto dir = test::temp_dir("pmat");
  const Camera c = some_cameras(false)[1];
  write_projection_matrix((dir / "c.P").string(), c);
  expect_same_projection(c, read_projection_matrix((dir / "c.P").string(), 640, 480));
  // MIT .Pmat.cal style and XML-wrapped (dancer) style.
  const Matrix34d P = c.P();
  std::ostringstream plain;
  plain.precision(17);
  for (int r = 0; r < 3; ++r) plain << P(r, 0) << ' ' << P(r, 1) << ' ' << P(r, 2) << ' ' << P(r, 3) << "\n";
  test::write_text(dir / "a.Pmat.cal", "CONTOUR\n" + plain.str());
  test::write_text(dir / "b.xml", "<?xml version=\"1.0\" ?>\n<camera>\n" + plain.str() + "</camera>\n");
  expect_same_projection(c, read_projection_matrix((dir / "a.Pmat.cal").string(), 640, 480));
  expect_same_projection(c, read_projection_matrix((dir / "b.xml").string(), 640, 480));
}

TEST(CameraIo, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("badcam");
  const std::string good_line = "v.png 500 0 320 0 500 240 0 0 1 1 0 0 0 1 0 0 0 1 0 0 2\n";
  struct Case { const char* name; std::string text; const char* expect; };
  const Case par[] = {
      {"count", "x\n" + good_line, "number of cameras"},
      {"absurd", "99999999999\n" + good_line, "not plausible"},
      {"trunc", "2\n" + good_line, "file ends"},
      {"short", "1\nv.png 500 0 320 0 500\n", "expected"},
      {"nan", "1\nv.png 500 0 320 0 500 240 0 0 1 1 0 0 0 1 0 0 0 1 nan 0 2\n", ""},
      {"notrot", "1\nv.png 500 0 320 0 500 240 0 0 1 2 0 0 0 1 0 0 0 1 0 0 2\n", "not a rotation"},
      {"extra", "1\n" + good_line + "junk\n", "unexpected"},
  };
  for (const Case& c : par) {
    const auto f = dir / (std::string(c.name) + "_par.txt");
    test::write_text(f, c.text);
    const std::string e = test::file_error_of([&] { read_middlebury_par(f.string(), 640, 480); });
    EXPECT_NE(e, "") << c.name;
    EXPECT_NE(e.find(f.string()), std::string::npos) << c.name << ": " << e;
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": " << e;
  }
  // Image size needed but the image is missing.
  test::write_text(dir / "m_par.txt", "1\n" + good_line);
  EXPECT_NE(test::file_error_of([&] { read_middlebury_par((dir / "m_par.txt").string()); }).find("pass the size"), std::string::npos);
  EXPECT_NE(test::file_error_of([&] { read_middlebury_par((dir / "missing_par.txt").string()); }).find("no such file"), std::string::npos);

  const Case pm[] = {{"eleven", "1 2 3 4 5 6 7 8 9 10 11\n", "exactly 12"},
                     {"word", "1 2 3 4 five 6 7 8 9 10 11 12\n", "not a number"},
                     {"singular", "1 0 0 0 0 1 0 0 0 0 0 1\n", "singular"},
                     {"inf", "1 0 0 0 0 1 0 0 0 0 1 inf\n", "not finite"}};
  for (const Case& c : pm) {
    const auto f = dir / (std::string(c.name) + ".P");
    test::write_text(f, c.text);
    const std::string e = test::file_error_of([&] { read_projection_matrix(f.string(), 10, 10); });
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": " << e;
    EXPECT_NE(e.find(f.string()), std::string::npos) << c.name << ": " << e;
  }

  const auto cm = dir / "colmap";
  std::filesystem::create_directories(cm);
  const Case cams[] = {{"model", "1 FISHEYE 640 480 1 2 3 4\n", "not supported"},
                       {"params", "1 PINHOLE 640 480 1 2 3\n", "takes 4 parameters"},
                       {"size", "1 PINHOLE -640 480 1 2 3 4\n", "positive integers"},
                       {"nan", "1 PINHOLE 640 480 nan 2 3 4\n", "finite"}};
  for (const Case& c : cams) {
    test::write_text(cm / "cameras.txt", c.text);
    test::write_text(cm / "images.txt", "1 1 0 0 0 0 0 0 1 a.png\n\n");
    const std::string e = test::file_error_of([&] { read_colmap_text(cm.string()); });
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": " << e;
    EXPECT_NE(e.find("cameras.txt:1"), std::string::npos) << c.name << ": " << e;
  }
  test::write_text(cm / "cameras.txt", "1 PINHOLE 640 480 500 500 320 240\n");
  const Case imgs[] = {{"cam", "1 1 0 0 0 0 0 0 7 a.png\n\n", "not defined"},
                       {"quat", "1 2 0 0 0 0 0 0 1 a.png\n\n", "quaternion"},
                       {"fields", "1 1 0 0 0 0 0 1 a.png\n\n", "10 fields"}};
  for (const Case& c : imgs) {
    test::write_text(cm / "images.txt", c.text);
    const std::string e = test::file_error_of([&] { read_colmap_text(cm.string()); });
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": " << e;
  }
  std::filesystem::remove(cm / "images.txt");
  EXPECT_NE(test::file_error_of([&] { read_colmap_text(cm.string()); }).find("no such file"), std::string::npos);
}

// The Tsinghua dome format (WD2 / lkB calibParamsI.txt): index, K with skew, k1 k2, [R|t].
TEST(CameraIo, DomeCalibrationReadsBlocksAndNamesErrors) {
  const auto dir = test::temp_dir("domecal");
  const std::string b0 = "0\n900 -1.5 520\n0.0 898 384\n0 0 1\n-0.04 0.06\n1 0 0 0\n0 1 0 0\n0 0 1 0\n\n";
  const std::string b1 = "1\n899 -1.0 506\n0.0 898 395\n0 0 1\n-0.03 0.05\n0 0 1 -7.5\n0 1 0 0.1\n-1 0 0 1.5\n\n";
  test::write_text(dir / "ok.txt", b0 + b1);
  const auto cams = read_dome_calibration((dir / "ok.txt").string(), 1024, 768);
  ASSERT_EQ(cams.size(), 2u);
  EXPECT_EQ(cams[0].name(), "cam0");
  EXPECT_EQ(cams[1].name(), "cam1");
  EXPECT_DOUBLE_EQ(cams[0].K()(0, 1), -1.5);  // skew kept
  EXPECT_DOUBLE_EQ(cams[1].distortion().k1, -0.03);
  EXPECT_DOUBLE_EQ(cams[1].distortion().k2, 0.05);
  EXPECT_DOUBLE_EQ(cams[1].t().x(), -7.5);
  EXPECT_NEAR((cams[1].R() - (Eigen::Matrix3d() << 0, 0, 1, 0, 1, 0, -1, 0, 0).finished()).norm(), 0, 1e-12);
  // A world point on camera 0's axis projects to its principal point (no distortion there).
  EXPECT_NEAR((cams[0].project({0, 0, 5}) - Eigen::Vector2d(520, 384)).norm(), 0, 1e-9);

  struct Case { const char* name; std::string text; const char* expect; };
  const Case bad[] = {
      {"empty", "\n", "no camera"},
      {"index", "zero\n", "camera index"},
      {"trunc", "0\n900 0 520\n0 898 384\n0 0 1\n-0.04\n", "distortion coefficient of camera 0"},
      {"word", "0\n900 0 520\n0 898 384\n0 0 1\n-0.04 0.06\n1 0 0 0\n0 1 0 x\n0 0 1 0\n", "t entry of camera 0"},
      {"twice", b0 + b0, "appears twice"},
      {"notrot", "0\n900 0 520\n0 898 384\n0 0 1\n0 0\n2 0 0 0\n0 1 0 0\n0 0 1 0\n", "not a rotation"},
      {"focal", "0\n-900 0 520\n0 898 384\n0 0 1\n0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n", "cam0"},
      {"negative", "-3\n", "not plausible"},
  };
  for (const Case& c : bad) {
    const auto f = dir / (std::string(c.name) + ".txt");
    test::write_text(f, c.text);
    const std::string e = test::file_error_of([&] { read_dome_calibration(f.string(), 1024, 768); });
    EXPECT_NE(e.find(f.string()), std::string::npos) << c.name << ": " << e;
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": " << e;
  }
  EXPECT_THROW(read_dome_calibration((dir / "ok.txt").string(), 0, 768), InvalidInput);
  EXPECT_NE(test::file_error_of([&] { read_dome_calibration((dir / "missing.txt").string(), 1024, 768); }).find("missing.txt"), std::string::npos);
}

TEST(CameraIo, MiddleburyStereoCalibReadsThe2014Format) {
  const auto dir = test::temp_dir("mbcalib");
  const auto p = (dir / "calib.txt").string();
  // The Adirondack calib.txt of Middlebury 2014 (full size).
  test::write_text(p, "cam0=[4161.221 0 1445.577; 0 4161.221 984.686; 0 0 1]\ncam1=[4161.221 0 1654.636; 0 4161.221 984.686; 0 0 1]\n"
           "doffs=209.059\nbaseline=176.252\nwidth=2880\nheight=1988\nndisp=280\nisint=0\nvmin=33\nvmax=218\ndyavg=0.187\ndymax=0.546\n");
  const RectifiedPairCalibration c = read_middlebury_stereo_calib(p);
  EXPECT_DOUBLE_EQ(c.f, 4161.221);
  EXPECT_DOUBLE_EQ(c.cx0, 1445.577);
  EXPECT_DOUBLE_EQ(c.cx1, 1654.636);
  EXPECT_DOUBLE_EQ(c.cy, 984.686);
  EXPECT_DOUBLE_EQ(c.doffs, 209.059);
  EXPECT_DOUBLE_EQ(c.baseline, 176.252);
  EXPECT_EQ(c.width, 2880);
  EXPECT_EQ(c.ndisp, 280);
}

TEST(CameraIo, MalformedStereoCalibGivesClearErrors) {
  const auto dir = test::temp_dir("mbcalib_bad");
  const auto p = (dir / "calib.txt").string();
  const std::string cam0 = "cam0=[100 0 50; 0 100 40; 0 0 1]\n", cam1 = "cam1=[100 0 60; 0 100 40; 0 0 1]\n";
  auto err = [&](const std::string& text) {
    test::write_text(p, text);
    return test::file_error_of([&] { read_middlebury_stereo_calib(p); });
  };
  EXPECT_NE(err(cam0 + cam1).find("missing baseline"), std::string::npos);
  EXPECT_NE(err(cam0 + "baseline=1\n").find("missing cam1"), std::string::npos);
  EXPECT_NE(err(cam0 + cam1 + "baseline=-3\n").find(":3: baseline must be > 0"), std::string::npos);
  EXPECT_NE(err("cam0=[100 0 50; 0 100 40]\n" + cam1 + "baseline=1\n").find("3 rows of 3 numbers"), std::string::npos);
  EXPECT_NE(err("cam0=[100 0 50; 0 100 x; 0 0 1]\n").find("'x' is not a number"), std::string::npos);
  EXPECT_NE(err("cam0=100 0 50\n").find("matrix in brackets"), std::string::npos);
  EXPECT_NE(err(cam0 + cam0).find("appears twice"), std::string::npos);
  EXPECT_NE(err(cam0 + cam1 + "baseline=1\ncolour=3\n").find("unknown key 'colour'"), std::string::npos);
  EXPECT_NE(err(cam0 + cam1 + "baseline=1\ndoffs=3\n").find("cx1 - cx0"), std::string::npos);
  EXPECT_NE(err(cam0 + "cam1=[90 0 60; 0 90 40; 0 0 1]\nbaseline=1\n").find("not rectified"), std::string::npos);
  EXPECT_NE(err(cam0 + cam1 + "baseline=1\nwidth=2.5\n").find("non-negative integer"), std::string::npos);
  EXPECT_NE(err("no equals sign\n").find(":1: expected 'key=value'"), std::string::npos);
  EXPECT_NE(test::file_error_of([&] { read_middlebury_stereo_calib((dir / "none.txt").string()); }).find("none.txt"), std::string::npos);
  // Valid without doffs: derived from the principal points.
  test::write_text(p, cam0 + cam1 + "baseline=2\n");
  EXPECT_DOUBLE_EQ(read_middlebury_stereo_calib(p).doffs, 10.0);
}
