#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "test_util.h"
#include "tbsp/core/error.h"
#include "tbsp/io/mocap_io.h"

using namespace tbsp;

namespace {
struct Case { const char* name; std::string text; const char* expect; };
// Writes each case to DIR/NAME.EXT, reads it with `read`, and expects a FileError naming the
// file and containing the expected phrase.
template <typename Read>
void expect_file_errors(const std::filesystem::path& dir, const char* ext, const std::vector<Case>& cases, Read read) {
  for (const Case& c : cases) {
    const auto f = dir / (std::string(c.name) + ext);
    test::write_text(f, c.text);
    const std::string e = test::file_error_of([&] { read(f.string()); });
    EXPECT_NE(e, "") << c.name;
    EXPECT_NE(e.find(c.expect), std::string::npos) << c.name << ": '" << e << "'";
    EXPECT_NE(e.find(f.string()), std::string::npos) << c.name;
  }
}
MarkerTrajectories some_markers() {
  MarkerTrajectories m;
  m.names = {"LASI", "RASI", "C7"};
  m.frame_rate = 100;
  m.first_frame = 5;
  m.units = "mm";
  m.data.resize(4, 9);
  for (int f = 0; f < 4; ++f)
    for (int k = 0; k < 9; ++k) m.data(f, k) = 10.0 * f + k + 0.125;
  m.data.block<1, 3>(2, 3).setConstant(std::numeric_limits<double>::quiet_NaN());  // a gap
  return m;
}

// A minimal Intel-float C3D written byte by byte (c3d.org layout): header, one parameter
// block with POINT:USED/LABELS/RATE/UNITS, data from block 3.
std::string make_c3d(int npoints, int nframes, float scale, int processor = 84) {
  std::string f(512 * 3, '\0');
  auto put16 = [&](std::size_t at, int v) { std::int16_t x = static_cast<std::int16_t>(v); std::memcpy(&f[at], &x, 2); };
  auto putf = [&](std::size_t at, float v) { std::memcpy(&f[at], &v, 4); };
  f[0] = 2;
  f[1] = 0x50;
  put16(2, npoints);
  put16(4, 0);
  put16(6, 1);
  put16(8, nframes);
  putf(12, scale);
  put16(16, 3);
  putf(20, 50.0f);
  std::size_t p = 512;
  f[p + 2] = 1;
  f[p + 3] = static_cast<char>(processor);
  p += 4;
  auto group = [&](const std::string& name, int id) {
    f[p] = static_cast<char>(name.size());
    f[p + 1] = static_cast<char>(-id);
    std::memcpy(&f[p + 2], name.data(), name.size());
    put16(p + 2 + name.size(), 3);  // next record after offset(2) + desc len(1)
    f[p + 4 + name.size()] = 0;
    p += 5 + name.size();
  };
  auto param = [&](const std::string& name, int gid, int type, std::vector<int> dims, const std::string& data) {
    f[p] = static_cast<char>(name.size());
    f[p + 1] = static_cast<char>(gid);
    std::memcpy(&f[p + 2], name.data(), name.size());
    const std::size_t off = p + 2 + name.size();
    std::size_t q = off + 2;
    f[q] = static_cast<char>(type);
    f[q + 1] = static_cast<char>(dims.size());
    for (std::size_t k = 0; k < dims.size(); ++k) f[q + 2 + k] = static_cast<char>(dims[k]);
    q += 2 + dims.size();
    std::memcpy(&f[q], data.data(), data.size());
    q += data.size();
    f[q] = 0;  // description length
    put16(off, static_cast<int>(q + 1 - off));
    p = q + 1;
  };
  group("POINT", 1);
  std::string used(2, '\0');
  { std::int16_t u = static_cast<std::int16_t>(npoints); std::memcpy(&used[0], &u, 2); }
  param("USED", 1, 2, {}, used);
  std::string labels;
  for (int i = 0; i < npoints; ++i) { std::string l = "MK" + std::to_string(i); l.resize(4, ' '); labels += l; }
  param("LABELS", 1, -1, {4, npoints}, labels);
  param("UNITS", 1, -1, {2}, "mm");
  f[p] = 0;  // end of parameters
  // data
  f.resize(1024 + static_cast<std::size_t>(std::max(1, nframes * npoints * 16 / 512 + 1)) * 512, '\0');
  for (int fr = 0; fr < nframes; ++fr)
    for (int k = 0; k < npoints; ++k) {
      const std::size_t at = 1024 + static_cast<std::size_t>(fr * npoints + k) * 16;
      putf(at, 100.0f * fr + k);
      putf(at + 4, 1.5f);
      putf(at + 8, -2.0f);
      putf(at + 12, (fr == 1 && k == 0) ? -1.0f : 0.0f);  // one gap
    }
  return f;
}
}  // namespace

TEST(Trc, RoundTripKeepsValuesAndGaps) {
  const auto dir = test::temp_dir("trc");
  const MarkerTrajectories m = some_markers();
  write_trc((dir / "a.trc").string(), m);
  const MarkerTrajectories b = read_trc((dir / "a.trc").string());
  EXPECT_EQ(b.names, m.names);
  EXPECT_EQ(b.numFrames(), 4);
  EXPECT_EQ(b.first_frame, 5);
  EXPECT_EQ(b.units, "mm");
  EXPECT_DOUBLE_EQ(b.frame_rate, 100);
  EXPECT_FALSE(b.valid(2, 1));
  EXPECT_TRUE(b.valid(2, 0));
  for (int f = 0; f < 4; ++f)
    for (int k = 0; k < 3; ++k)
      if (m.valid(f, k)) { EXPECT_LT((b.position(f, k) - m.position(f, k)).norm(), 1e-9); }
  EXPECT_EQ(b.markerIndex("C7"), 2);
  EXPECT_EQ(b.markerIndex("nope"), -1);
}

TEST(Trc, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("trcbad");
  write_trc((dir / "good.trc").string(), some_markers());
  std::ifstream in(dir / "good.trc");
  std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto replace = [&](const std::string& a, const std::string& b) { std::string s = good; s.replace(s.find(a), a.size(), b); return s; };
  expect_file_errors(dir, ".trc", {
      {"magic", "Hello\n" + good.substr(good.find('\n') + 1), "PathFileType"},
      {"truncated_rows", good.substr(0, good.rfind("8\t")), "NumFrames"},
      {"truncated_header", good.substr(0, 60), "file ends"},
      {"absurd", replace("\t4\t3\tmm", "\t4\t99999999\tmm"), "NumMarkers"},
      {"nan", replace("0.125", "nan"), "NaN"},
      {"word", replace("0.125", "abc"), "not a number"},
      {"rate", replace("100\t100\t4", "-1\t100\t4"), "DataRate"},
      {"empty", "", "file ends"},
  }, [](const std::string& f) { read_trc(f); });
  EXPECT_NE(test::file_error_of([&] { read_trc((dir / "missing.trc").string()); }).find("no such file"), std::string::npos);
}

TEST(C3d, MinimalIntelFloatFileParses) {
  const auto dir = test::temp_dir("c3d");
  test::write_text(dir / "a.c3d", make_c3d(3, 4, -1.0f));
  const MarkerTrajectories m = read_c3d((dir / "a.c3d").string());
  EXPECT_EQ(m.numMarkers(), 3);
  EXPECT_EQ(m.numFrames(), 4);
  EXPECT_EQ(m.names[2], "MK2");
  EXPECT_EQ(m.units, "mm");
  EXPECT_DOUBLE_EQ(m.frame_rate, 50);
  EXPECT_FALSE(m.valid(1, 0));
  EXPECT_TRUE(m.valid(1, 1));
  EXPECT_DOUBLE_EQ(m.position(3, 2).x(), 302);
  EXPECT_DOUBLE_EQ(m.position(3, 2).z(), -2);
}

TEST(C3d, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("c3dbad");
  const std::string good = make_c3d(3, 4, -1.0f);
  std::string magic = good; magic[1] = 0x51;
  std::string dec = make_c3d(3, 4, -1.0f, 85);
  std::string mips = make_c3d(3, 4, -1.0f, 86);
  std::string absurd = good; { std::int16_t v = 30000; std::memcpy(&absurd[8], &v, 2); }
  std::string npts = good; { std::int16_t v = 32000; std::memcpy(&npts[2], &v, 2); }
  std::string zero_scale = good; { float v = 0; std::memcpy(&zero_scale[12], &v, 4); }
  std::string pblock = good; pblock[0] = 0;
  std::string badtype = good; badtype[512 + 4 + 5 + 5 + 2 + 4 + 2] = 7;  // type byte of POINT:USED
  expect_file_errors(dir, ".c3d", {
      {"short", good.substr(0, 100), "shorter than the 512-byte"},
      {"magic", magic, "wrong magic"},
      {"dec", dec, "DEC"},
      {"mips", mips, "MIPS"},
      {"frames", absurd, "truncated"},
      {"points", npts, "POINT:USED"},
      {"scale", zero_scale, "scale"},
      {"pblock", pblock, "parameter section"},
      {"type", badtype, "type"},
      {"truncated", good.substr(0, 1024 + 20), "truncated"},
      {"params_cut", good.substr(0, 530), ""},
  }, [](const std::string& f) { read_c3d(f); });
}

TEST(Bvh, RoundTripAndForwardKinematics) {
  const auto dir = test::temp_dir("bvh");
  test::write_text(dir / "a.bvh",
        "HIERARCHY\nROOT hip\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        " JOINT knee\n {\n  OFFSET 0 -10 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -8 0\n  }\n }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.04\n0 100 0 0 0 0 0 0 0\n5 100 0 90 0 0 0 0 0\n");
  const BvhMotion m = read_bvh((dir / "a.bvh").string());
  EXPECT_EQ(m.numJoints(), 2);
  EXPECT_EQ(m.joints.size(), 3u);
  EXPECT_EQ(m.numFrames(), 2);
  EXPECT_DOUBLE_EQ(m.frame_time, 0.04);
  const auto p0 = m.jointPositions(0);
  EXPECT_LT((p0.row(2) - Eigen::RowVector3d(0, 82, 0)).norm(), 1e-12);
  // Frame 1: root rotated 90 degrees about z: the leg points along +x.
  const auto p1 = m.jointPositions(1);
  EXPECT_LT((p1.row(1) - Eigen::RowVector3d(15, 100, 0)).norm(), 1e-9);
  EXPECT_LT((p1.row(2) - Eigen::RowVector3d(23, 100, 0)).norm(), 1e-9);
  write_bvh((dir / "b.bvh").string(), m);
  const BvhMotion b = read_bvh((dir / "b.bvh").string());
  EXPECT_EQ(b.numJoints(), 2);
  EXPECT_LT((b.motion - m.motion).norm(), 1e-12);
  EXPECT_LT((b.jointPositions(1) - p1).norm(), 1e-9);
}

TEST(Bvh, MalformedFilesGiveClearErrors) {
  const auto dir = test::temp_dir("bvhbad");
  const std::string head = "HIERARCHY\nROOT hip\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\n";
  expect_file_errors(dir, ".bvh", {
      {"magic", "HIERARCHIES\n", "HIERARCHY"},
      {"truncated", head.substr(0, 40), "expected 'CHANNELS'"},
      {"truncated2", head.substr(0, 21), "file ends"},
      {"frames", head + "Frames: 3\nFrame Time: 0.1\n1 2 3\n4 5 6\n", "truncated"},
      {"absurd", head + "Frames: 9999999\nFrame Time: 0.1\n1 2 3\n", "cannot fit"},
      {"nan", head + "Frames: 1\nFrame Time: 0.1\n1 nan 3\n", "finite"},
      {"channel", "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 1 Wrotation\n}\nMOTION\n", "unknown channel"},
      {"channels", "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 99\n}\nMOTION\n", "channels"},
      {"time", head + "Frames: 1\nFrame Time: -1\n1 2 3\n", "positive"},
      {"extra", head + "Frames: 1\nFrame Time: 0.1\n1 2 3\n4\n", "unexpected"},
      {"brace", "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 0\n", "missing '}'"},
  }, [](const std::string& f) { read_bvh(f); });
  // Deep nesting does not overflow the stack.
  std::string deep = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 0\n";
  for (int i = 0; i < 5000; ++i) deep += "JOINT j\n{\nOFFSET 0 0 0\nCHANNELS 0\n";
  test::write_text(dir / "deep.bvh", deep);
  EXPECT_NE(test::file_error_of([&] { read_bvh((dir / "deep.bvh").string()); }).find("deeper"), std::string::npos);
}
