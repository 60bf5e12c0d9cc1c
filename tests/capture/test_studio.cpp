#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <cstdio>
#include <cstdlib>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/studio.h"

using namespace tbsp;

namespace {
Studio small_studio(const std::filesystem::path& dir, int ncam = 3, int nframes = 5) {
  Studio s;
  s.path = (dir / "studio.yaml").string();
  s.name = "unit";
  s.frame_rate = 30;
  s.first_frame = 10;
  s.last_frame = 10 + nframes - 1;
  for (int c = 0; c < ncam; ++c) {
    const double a = 2 * M_PI * c / ncam;
    StudioCamera sc;
    Camera cam = Camera::lookAt("cam" + std::to_string(c), 32, 24, 1.0, {2 * std::cos(a), 0.5, 2 * std::sin(a)}, {0, 0, 0}, {0, 1, 0});
    Distortion d;
    d.k1 = c == 1 ? -0.05 : 0.0;
    sc.camera = Camera(cam.name(), 32, 24, cam.K(), cam.R(), cam.t(), d);
    sc.images = "images/cam" + std::to_string(c) + "/%04d.png";
    sc.silhouettes = "sil/cam" + std::to_string(c) + "_%d.png";
    s.cameras.push_back(sc);
    std::filesystem::create_directories(dir / "images" / ("cam" + std::to_string(c)));
    std::filesystem::create_directories(dir / "sil");
    for (int f = s.first_frame; f <= s.last_frame; ++f) {
      cv::imwrite(s.imagePath(c, f), cv::Mat(24, 32, CV_8UC3, cv::Scalar(c, f, 7)));
      cv::Mat sil(24, 32, CV_8UC1, cv::Scalar(0));
      sil(cv::Rect(5, 5, 10, 10)).setTo(200);
      cv::imwrite(s.silhouettePath(c, f), sil);
    }
  }
  s.ground_truth = "gt/%03d.ply";
  return s;
}

// One camera whose frames 10..13 are a 4-frame MJPG video of grey levels 0, 40, 80, 120; false
// when OpenCV cannot write MJPG here.
bool video_studio(const std::filesystem::path& dir, Studio& s) {
  s = small_studio(dir, 1, 4);
  cv::VideoWriter vw((dir / "cam0.avi").string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30, cv::Size(32, 24));
  if (!vw.isOpened()) return false;
  for (int f = 0; f < 4; ++f) vw.write(cv::Mat(24, 32, CV_8UC3, cv::Scalar(40 * f, 40 * f, 40 * f)));
  vw.release();
  s.cameras[0].images.clear();
  s.cameras[0].video = "cam0.avi";
  s.ground_truth.clear();
  return true;
}

}  // namespace

TEST(Studio, FramePatterns) {
  EXPECT_EQ(expand_frame_pattern("img_%04d.png", 7), "img_0007.png");
  EXPECT_EQ(expand_frame_pattern("%d", 123), "123");
  EXPECT_EQ(expand_frame_pattern("a%%b%3d", 5), "a%b  5");
  EXPECT_THROW(expand_frame_pattern("none.png", 1), InvalidInput);
  EXPECT_THROW(expand_frame_pattern("%d_%d", 1), InvalidInput);
  EXPECT_THROW(expand_frame_pattern("%s", 1), InvalidInput);
  EXPECT_THROW(expand_frame_pattern("%00d", 1), InvalidInput);
}

TEST(Studio, WrittenCamerasReadBackProjectToTheSamePixels) {
  const auto dir = test::temp_dir("studio_rt");
  const Studio s = small_studio(dir);
  write_studio(s.path, s);
  const Studio r = read_studio(dir.string());  // a directory with studio.yaml works too
  ASSERT_EQ(r.cameras.size(), s.cameras.size());
  EXPECT_EQ(r.first_frame, 10);
  EXPECT_EQ(r.numFrames(), 5);
  EXPECT_EQ(r.ground_truth, "gt/%03d.ply");
  double worst = 0;
  for (std::size_t c = 0; c < s.cameras.size(); ++c)
    for (const Eigen::Vector3d& X : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.3, 0.2, -0.1), Eigen::Vector3d(-0.2, -0.3, 0.25)})
      worst = std::max(worst, (r.cameras[c].camera.project(X) - s.cameras[c].camera.project(X)).norm());
  EXPECT_LT(worst, 1e-9);
}

TEST(Studio, StreamsFramesAndListsMissingFiles) {
  const auto dir = test::temp_dir("studio_stream");
  Studio s = small_studio(dir);
  write_studio(s.path, s);
  s = read_studio(s.path);
  StudioCheck chk = check_studio(s);
  EXPECT_EQ(chk.files_missing, 5);  // the ground-truth meshes were never written
  EXPECT_NE(chk.summary().find("gt/010.ply"), std::string::npos) << chk.summary();
  s.ground_truth.clear();
  EXPECT_TRUE(check_studio(s).ok()) << check_studio(s).summary();

  StudioFrameStream stream(s, {});
  StudioFrame fr;
  int n = 0;
  while (stream.next(fr)) {
    EXPECT_EQ(fr.frame, 10 + n);
    ASSERT_EQ(fr.images.size(), 3u);
    EXPECT_EQ(fr.images[2].at<cv::Vec3b>(0, 0), cv::Vec3b(2, static_cast<unsigned char>(10 + n), 7));
    EXPECT_EQ(fr.silhouettes[1].at<std::uint8_t>(7, 7), 255);  // thresholded
    EXPECT_EQ(fr.silhouettes[1].at<std::uint8_t>(0, 0), 0);
    ++n;
  }
  EXPECT_EQ(n, 5);
  // Sub-range with a step.
  StudioFrameStream sub(s, {true, false, 11, 14, 2});
  std::vector<int> got;
  while (sub.next(fr)) { got.push_back(fr.frame); EXPECT_TRUE(fr.silhouettes[0].empty()); }
  EXPECT_EQ(got, (std::vector<int>{11, 13}));
  EXPECT_THROW(StudioFrameStream(s, {true, true, 0, 3, 1}), InvalidInput);

  // Remove two frames: the check names them, the stream fails at the first with the file name.
  std::filesystem::remove(s.imagePath(1, 12));
  std::filesystem::remove(s.silhouettePath(2, 13));
  chk = check_studio(s);
  EXPECT_EQ(chk.files_missing, 2);
  EXPECT_NE(chk.summary().find("cam1/0012.png"), std::string::npos);
  EXPECT_NE(chk.summary().find("cam2_13.png"), std::string::npos);
  StudioFrameStream broken(s, {});
  EXPECT_TRUE(broken.next(fr));
  EXPECT_TRUE(broken.next(fr));
  const std::string e = test::file_error_of([&] { broken.next(fr); });
  EXPECT_NE(e.find("cam1/0012.png"), std::string::npos) << e;
  EXPECT_NE(e.find("missing"), std::string::npos) << e;
  // An image of the wrong size is reported.
  cv::imwrite(s.imagePath(0, 10), cv::Mat(10, 10, CV_8UC3));
  EXPECT_NE(check_studio(s).summary().find("10x10"), std::string::npos);
  StudioFrameStream sized(s, {});
  EXPECT_NE(test::file_error_of([&] { sized.next(fr); }).find("differs from the calibrated"), std::string::npos);
}

TEST(Studio, VideoCamerasStream) {
  const auto dir = test::temp_dir("studio_video");
  Studio s;
  if (!video_studio(dir, s)) GTEST_SKIP() << "OpenCV has no MJPG writer here";
  write_studio(s.path, s);
  s = read_studio(s.path);
  EXPECT_TRUE(check_studio(s).ok()) << check_studio(s).summary();
  StudioFrameStream st(s, {true, false, 11, 13, 2});
  StudioFrame fr;
  ASSERT_TRUE(st.next(fr));
  EXPECT_EQ(fr.frame, 11);
  EXPECT_NEAR(fr.images[0].at<cv::Vec3b>(12, 16)[0], 40, 6);  // the second video frame
  ASSERT_TRUE(st.next(fr));
  EXPECT_NEAR(fr.images[0].at<cv::Vec3b>(12, 16)[0], 120, 6);
  EXPECT_FALSE(st.next(fr));
}

// Videos are decoded by a module loaded on first use (capture_io/src/video_reader.h): without it
// a video studio fails with a message naming the module and the fix, and nothing else breaks.
TEST(Studio, AMissingVideoModuleIsNamedWithTheFix) {
  const auto dir = test::temp_dir("studio_video_module");
  Studio s;
  if (!video_studio(dir, s)) GTEST_SKIP() << "OpenCV has no MJPG writer here";
  // in a fresh process (the module is loaded once per process): the variable names a file that
  // is not there, so it is the only candidate and the stream reports it
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        setenv("TBSP_VIDEO_MODULE", "/nonexistent/libtbsp_video.so", 1);
        const std::string problems = check_studio(s).summary();
        StudioFrameStream st(s, {true, false, 10, 11, 1});
        StudioFrame fr;
        try {
          st.next(fr);
        } catch (const FileError& e) {
          std::fprintf(stderr, "check: %s\nstream: %s\n", problems.c_str(), e.what());
          std::exit(3);
        }
        std::exit(0);
      },
      ::testing::ExitedWithCode(3), "check: .*cam0.avi.*video module libtbsp_video.so(.|\n)*stream: .*/nonexistent/libtbsp_video.so \\(no such file\\)(.|\n)*Fix: .*TBSP_VIDEO_MODULE");
}

TEST(Studio, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("studio_bad");
  const std::string cam = "  - name: a\n    width: 32\n    height: 24\n    K: [100, 0, 16, 0, 100, 12, 0, 0, 1]\n"
                          "    R: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n    t: [0, 0, 2]\n";
  const std::string head = "tbsp_studio: 1\nframes: {first: 0, last: 3}\ncameras:\n";
  struct Case { const char* name; std::string text; const char* expect; };
  const Case cases[] = {
      {"syntax", head + cam + "  - [unclosed\n", "YAML syntax error"},
      {"version", "tbsp_studio: 2\n", "not supported"},
      {"noversion", "frames: {first: 0, last: 3}\n", "tbsp_studio"},
      {"notmap", "- 1\n- 2\n", "mapping"},
      {"noframes", "tbsp_studio: 1\ncameras: []\n", "'frames' is missing"},
      {"range", "tbsp_studio: 1\nframes: {first: 5, last: 3}\ncameras: []\n", "empty frame range"},
      {"nocams", "tbsp_studio: 1\nframes: {first: 0, last: 3}\ncameras: []\n", "non-empty list"},
      {"K", head + "  - name: a\n    width: 32\n    height: 24\n    K: [100, 0, 16]\n    R: [1,0,0,0,1,0,0,0,1]\n    t: [0,0,2]\n", "9 numbers"},
      {"Rnot", head + "  - name: a\n    width: 32\n    height: 24\n    K: [100,0,16,0,100,12,0,0,1]\n    R: [2,0,0,0,1,0,0,0,1]\n    t: [0,0,2]\n", "not a rotation"},
      {"P", head + "  - name: a\n    width: 32\n    height: 24\n    P: [1,0,0,0, 0,1,0,0, 0,0,0,1]\n", "singular"},
      {"Pnan", head + "  - name: a\n    width: 32\n    height: 24\n    P: [1,0,0,0, 0,1,0,0, 0,0,.nan,1]\n", "not finite"},
      {"word", head + "  - name: a\n    width: big\n", "not a number"},
      {"size", head + "  - name: a\n    width: -3\n    height: 24\n", "not plausible"},
      {"dup", head + cam + cam, "duplicate camera name"},
      {"pattern", head + cam + "    images: img.png\n", "exactly one %d"},
      {"unknown", head + cam + "colour: red\n", "unknown key 'colour'"},
      {"both", head + cam + "    images: a%d.png\n    video: a.avi\n", "either images or video"},
  };
  for (const Case& c : cases) {
    const auto f = dir / (std::string(c.name) + ".yaml");
    test::write_text(f, c.text);
    const std::string e = test::file_error_of([&] { read_studio(f.string()); });
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": '" << e << "'";
    EXPECT_NE(e.find(f.string()), std::string::npos) << c.name << ": '" << e << "'";
  }
  // Line numbers point at the offending camera.
  test::write_text(dir / "line.yaml", head + cam + "  - name: b\n    width: 32\n    height: 24\n    K: [100,0,16,0,-100,12,0,0,1]\n    R: [1,0,0,0,1,0,0,0,1]\n    t: [0,0,2]\n");
  EXPECT_NE(test::file_error_of([&] { read_studio((dir / "line.yaml").string()); }).find("line.yaml:10:"), std::string::npos)
      << test::file_error_of([&] { read_studio((dir / "line.yaml").string()); });
  EXPECT_NE(test::file_error_of([&] { read_studio((dir / "missing.yaml").string()); }).find("no such file"), std::string::npos);
  test::write_text(dir / "empty.yaml", "");
  EXPECT_NE(test::file_error_of([&] { read_studio((dir / "empty.yaml").string()); }), "");
}
