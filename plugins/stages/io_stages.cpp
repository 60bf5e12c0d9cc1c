// Built-in sources and sinks: read-cloud, read-mesh, read-depth, read-markers, write-cloud, write-mesh,
// render-png. They wrap capture_io's readers and writers (no file-format code here).
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/features/normal_3d.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <filesystem>
#include <optional>
#include <sstream>

#include "stage_util.h"
#include "tbsp/io/cloud_io.h"
#include "tbsp/io/depth_io.h"
#include "tbsp/io/mesh_io.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/io/studio.h"
#include "tbsp/plugins/preview_render.h"

namespace fs = std::filesystem;

namespace tbsp::pipeline::builtin {
namespace {

bool is_pattern(const std::string& p) { return p.find('%') != std::string::npos; }

// Frames of a %d file pattern: every frame in [first, last] whose file exists; with last < 0,
// from `first` up to the first missing file.
std::vector<int> pattern_frames(const std::string& pattern, long long first, long long last) {
  std::vector<int> f;
  std::error_code ec;
  const long long stop = last >= 0 ? last : first + 10000000;
  for (long long i = first; i <= stop; ++i) {
    if (fs::exists(expand_frame_pattern(pattern, int(i)), ec)) f.push_back(int(i));
    else if (last < 0) break;
  }
  if (f.empty())
    throw FileError("'" + pattern + "': no file for frame " + std::to_string(first) + (last >= 0 ? " to " + std::to_string(last) : "") +
                    " (the pattern's %d is the frame number; set 'first'/'last' to the numbers on disk)");
  return f;
}

// A file per frame (a %d pattern: a frame source) or one file for every frame (read once).
class FileSource : public Stage {
public:
  FileSource(const Params& p, std::string port)
      : path_(p.text("path")), first_(p.integer("first")), last_(p.integer("last")), port_(std::move(port)) {}
  std::vector<int> frames() override { return is_pattern(path_) ? pattern_frames(path_, first_, last_) : std::vector<int>{}; }
  Ports process(FrameContext& ctx, const Ports&) override {
    if (cached_) return {{port_, *cached_}};
    const Data d = read(is_pattern(path_) ? expand_frame_pattern(path_, ctx.frame) : path_);
    if (!is_pattern(path_)) cached_ = d;
    return {{port_, d}};
  }

protected:
  virtual Data read(const std::string& file) const = 0;

private:
  std::string path_;
  long long first_, last_;
  std::string port_;
  std::optional<Data> cached_;
};

class ReadCloud : public FileSource {
public:
  explicit ReadCloud(const Params& p) : FileSource(p, "cloud") {}

protected:
  Data read(const std::string& file) const override {
    bool normals = false;
    auto c = read_cloud_normals(file, &normals);
    CloudN::Ptr kept = finite_points(*c);
    if (normals)  // keep the normals of the finite points
      for (std::size_t i = 0, j = 0; i < c->size(); ++i) {
        const auto& q = (*c)[i];
        if (std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z)) {
          (*kept)[j].normal_x = q.normal_x;
          (*kept)[j].normal_y = q.normal_y;
          (*kept)[j].normal_z = q.normal_z;
          ++j;
        }
      }
    if (kept->empty()) throw InvalidInput("'" + file + "': the cloud has no finite point");
    return Data::of(kept, normals);
  }
};

class ReadMesh : public FileSource {
public:
  explicit ReadMesh(const Params& p) : FileSource(p, "mesh") {}

protected:
  Data read(const std::string& file) const override { return Data::of(std::make_shared<const TriMesh>(read_mesh(file))); }
};

// .oni recordings (OpenNI2) or folders of 16-bit depth images.
class ReadDepth : public Stage {
public:
  explicit ReadDepth(const Params& p) : path_(p.text("path")), scale_(p.real("depth_scale")), normals_k_(int(p.integer("normals"))) {
    if (fs::path(path_).extension() == ".oni") return;
    if (!fs::is_directory(path_)) throw FileError("'" + path_ + "': neither an .oni recording nor a folder of depth images");
    for (const auto& e : fs::directory_iterator(path_)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".png" || ext == ".pgm" || ext == ".tif" || ext == ".tiff") files_.push_back(e.path().string());
    }
    std::sort(files_.begin(), files_.end());
    if (files_.empty()) throw FileError("'" + path_ + "': no depth images (.png .pgm .tif .tiff) in this folder");
    if (!p.text("studio").empty()) {  // intrinsics and pose of a studio camera
      const Studio st = read_studio(p.text("studio"));
      const std::string name = p.text("camera");
      std::string names;
      for (const auto& c : st.cameras) {
        names += (names.empty() ? "" : ", ") + c.camera.name();
        if (c.camera.name() == name) pose_ = c.camera;
      }
      if (!pose_) throw InvalidInput("'" + p.text("studio") + "' has no camera '" + name + "' (its cameras: " + names + ")");
      const double s = double(p.integer("stride"));
      K_.fx = pose_->K()(0, 0) / s;
      K_.fy = pose_->K()(1, 1) / s;
      K_.cx = pose_->K()(0, 2) / s;
      K_.cy = pose_->K()(1, 2) / s;
      return;
    }
    const std::string in = p.text("intrinsics");
    char c1 = 0, c2 = 0, c3 = 0;
    std::istringstream is(in);
    if (in.empty() || !(is >> K_.fx >> c1 >> K_.fy >> c2 >> K_.cx >> c3 >> K_.cy) || c1 != ',' || c2 != ',' || c3 != ',' || K_.fx <= 0 ||
        K_.fy <= 0)
      throw InvalidInput("a folder of depth images needs 'intrinsics: fx,fy,cx,cy' in pixels (e.g. 525,525,319.5,239.5), or "
                         "'studio' + 'camera'; got '" + in + "'");
  }
  std::vector<int> frames() override {
    std::vector<int> f;
    if (files_.empty()) {
      if (!OniReader::available())
        throw InvalidInput("'" + path_ + "': this tbsp was built without OpenNI2, so .oni recordings cannot be read (install libopenni2-dev and rebuild)");
      oni_ = std::make_unique<OniReader>(path_);
      for (int i = 0; i < oni_->info().depth_frames; ++i) f.push_back(i);
      if (f.empty()) throw FileError("'" + path_ + "': the recording has no depth frame");
    } else {
      for (std::size_t i = 0; i < files_.size(); ++i) f.push_back(int(i));
    }
    return f;
  }
  Ports process(FrameContext& ctx, const Ports&) override {
    CloudN::Ptr c;
    pcl::PointCloud<pcl::PointXYZ> xyz;  // organized: one point per pixel, NaN where no depth
    bool has_normals = false;
    if (oni_) {
      OniFrame fr;
      bool got = false;
      while (oni_->next(fr))
        if (fr.index == ctx.frame) { got = true; break; }
      if (!got || fr.depth.empty()) throw FileError("'" + path_ + "': depth frame " + std::to_string(ctx.frame) + " could not be read");
      xyz = depth_to_cloud(fr.depth, oni_->info().depth_intrinsics, oni_->info().depth_scale);
      c = finite_points(xyz);
    } else {
      const std::string& f = files_.at(std::size_t(ctx.frame));
      xyz = depth_to_cloud(read_depth_image(f), K_, scale_);
      c = finite_points(xyz);
      if (normals_k_ > 0 && c->size() > std::size_t(normals_k_)) {
        // PCA normals (pcl::NormalEstimation) turned towards the sensor at the origin
        pcl::NormalEstimation<pcl::PointNormal, pcl::PointNormal> ne;
        ne.setInputCloud(c);
        ne.setSearchMethod(pcl::search::KdTree<pcl::PointNormal>::Ptr(new pcl::search::KdTree<pcl::PointNormal>));
        ne.setKSearch(normals_k_);
        ne.setViewPoint(0, 0, 0);
        CloudN::Ptr n(new CloudN(*c));
        ne.compute(*n);
        c = finite_normals(*n);
        has_normals = true;
      }
    }
    CloudN::Ptr grid(new CloudN);
    pcl::copyPointCloud(xyz, *grid);  // keeps width x height and the NaN pixels; zero normals
    if (pose_) {  // camera -> world: X = Rᵀ (Xc - t), normals rotated
      const Eigen::Matrix3f Rt = pose_->R().transpose().cast<float>();
      const Eigen::Vector3f t = pose_->t().cast<float>();
      for (auto& q : *c) {
        q.getVector3fMap() = Rt * (q.getVector3fMap() - t);
        q.getNormalVector3fMap() = Rt * q.getNormalVector3fMap();
      }
      for (auto& q : *grid) q.getVector3fMap() = Rt * (q.getVector3fMap() - t);  // NaN stays NaN
      grid->sensor_origin_.head<3>() = -Rt * t;  // the camera centre: meshing's view point
    }
    if (c->empty()) throw InvalidInput("'" + path_ + "' frame " + std::to_string(ctx.frame) + ": no valid depth pixel");
    return {{"cloud", Data::of(c, has_normals)}, {"grid", Data::of(grid, false)}};
  }
  // an .oni recording is read forwards by one reader; image folders allow any frame order
  bool keeps_state() const override { return files_.empty(); }

private:
  std::string path_;
  double scale_;
  DepthIntrinsics K_;
  std::vector<std::string> files_;
  std::unique_ptr<OniReader> oni_;
  std::optional<Camera> pose_;  // with 'studio': clouds in world coordinates
  int normals_k_ = 0;
};

// Motion-capture markers (C3D / TRC): one cloud per frame, the markers seen in that frame.
class ReadMarkers : public Stage {
public:
  explicit ReadMarkers(const Params& p) : path_(p.text("path")), m_(read_markers(path_)) {
    if (m_.numFrames() == 0) throw FileError("'" + path_ + "': the file has no frame");
    if (p.boolean("metres")) {
      try {
        scale_ = marker_units_to_metres(m_.units);
      } catch (const InvalidInput& e) {
        throw InvalidInput("'" + path_ + "': " + e.what() + "; set 'metres: false' to keep the file's units");
      }
    }
  }
  std::vector<int> frames() override {
    std::vector<int> f(std::size_t(m_.numFrames()));
    for (int i = 0; i < m_.numFrames(); ++i) f[std::size_t(i)] = i;
    return f;
  }
  Ports process(FrameContext& ctx, const Ports&) override {
    CloudN::Ptr c(new CloudN);
    for (int k = 0; k < m_.numMarkers(); ++k)
      if (m_.valid(ctx.frame, k)) {
        pcl::PointNormal q;
        q.getVector3fMap() = (scale_ * m_.position(ctx.frame, k)).cast<float>();
        q.normal_x = q.normal_y = q.normal_z = 0;
        c->push_back(q);
      }
    if (c->empty()) throw InvalidInput("'" + path_ + "' frame " + std::to_string(ctx.frame) + ": no marker is seen in this frame");
    return {{"cloud", Data::of(c, false)}};
  }

private:
  std::string path_;
  MarkerTrajectories m_;
  double scale_ = 1.0;
};

std::string out_path(const std::string& pattern, int frame) { return is_pattern(pattern) ? expand_frame_pattern(pattern, frame) : pattern; }

class WriteMesh : public Stage {
public:
  explicit WriteMesh(const Params& p) : path_(p.text("path")), binary_(p.boolean("binary")) {}
  Ports process(FrameContext& ctx, const Ports& in) override {
    MeshWriteOptions o;
    o.binary = binary_;
    write_mesh(ctx.stage_output(out_path(path_, ctx.frame)), *in.at("mesh").mesh, o, mesh_format_from_path(path_));
    return {};
  }

private:
  std::string path_;
  bool binary_;
};

class WriteCloud : public Stage {
public:
  explicit WriteCloud(const Params& p) : path_(p.text("path")), binary_(p.boolean("binary")) {}
  Ports process(FrameContext& ctx, const Ports& in) override {
    const Data& d = in.at("cloud");
    pcl::PCLPointCloud2 blob;
    if (d.has_normals) {
      pcl::toPCLPointCloud2(*d.cloud, blob);
    } else {
      pcl::PointCloud<pcl::PointXYZ> xyz;
      xyz.reserve(d.cloud->size());
      for (const auto& q : *d.cloud) xyz.push_back(pcl::PointXYZ(q.x, q.y, q.z));
      pcl::toPCLPointCloud2(xyz, blob);
    }
    write_cloud(ctx.stage_output(out_path(path_, ctx.frame)), blob, binary_);
    return {};
  }

private:
  std::string path_;
  bool binary_;
};

class RenderPng : public Stage {
public:
  explicit RenderPng(const Params& p) : path_(p.text("path")) {
    o_.azimuth_deg = p.real("azimuth");
    o_.elevation_deg = p.real("elevation");
    o_.panel_width = o_.panel_height = int(p.integer("size"));
  }
  Ports process(FrameContext& ctx, const Ports& in) override {
    RenderPanel panel(*in.at("mesh").mesh, ctx.node + " frame " + std::to_string(ctx.frame));
    if (auto it = in.find("cloud"); it != in.end()) {
      const auto& c = *it->second.cloud;
      panel.points.resize(Eigen::Index(c.size()), 3);
      for (std::size_t i = 0; i < c.size(); ++i) panel.points.row(Eigen::Index(i)) << c[i].x, c[i].y, c[i].z;
    }
    render_panels_png(ctx.stage_output(out_path(path_, ctx.frame)), {panel}, o_);
    return {};
  }

private:
  std::string path_;
  RenderOptions o_;
};

}  // namespace

void register_io_stages(Registry& r) {
  const ParamSpec first = ParamSpec::integer("first", "0", "with a %d pattern: first frame number", 0, 1e9);
  const ParamSpec last = ParamSpec::integer("last", "-1", "with a %d pattern: last frame number (-1: up to the first missing file)", -1, 1e9);
  {
    StageInfo s{"read-cloud", "reads a point cloud (.pcd .ply .obj .off .vtk) per frame, or one cloud used by every frame"};
    s.params = {ParamSpec::input_path("path", "the cloud file, or a pattern such as scans/%04d.pcd (frame source)", true), first, last};
    s.outputs = {{"cloud", DataType::Cloud, "the finite points (with the file's normals when it has them)"}};
    r.add(s, [](const Params& p) { return std::make_unique<ReadCloud>(p); });
  }
  {
    StageInfo s{"read-mesh", "reads a triangle mesh (.ply .obj .off .vtk) per frame, or one mesh used by every frame (e.g. a template)"};
    s.params = {ParamSpec::input_path("path", "the mesh file, or a pattern such as seq/%04d.ply (frame source)", true), first, last};
    s.outputs = {{"mesh", DataType::Mesh, "the mesh"}};
    r.add(s, [](const Params& p) { return std::make_unique<ReadMesh>(p); });
  }
  {
    StageInfo s{"read-depth", "depth-sensor replay: an OpenNI .oni recording or a folder of 16-bit depth images, one cloud per frame"};
    s.params = {ParamSpec::input_path("path", ".oni file or folder of depth images (.png .pgm .tif .tiff, sorted by name)", true),
                ParamSpec::text("intrinsics", "", "folders: fx,fy,cx,cy in pixels (.oni: from the recording)"),
                ParamSpec::real("depth_scale", "0.001", "folders: metres per raw depth unit (TUM and tbsp synth-studio: 0.0002)", 1e-9, 1e3),
                ParamSpec::input_path("studio", "folders: a studio.yaml whose camera gives intrinsics and pose (clouds in world coordinates)", false),
                ParamSpec::text("camera", "", "with 'studio': the camera's name"),
                ParamSpec::integer("stride", "1", "with 'studio': the camera's pixels per depth pixel (synth-studio --scan-stride)", 1, 64),
                ParamSpec::integer("normals", "0", "folders: estimate normals from this many neighbours, turned to the sensor (0: none)", 0, 1000)};
    s.outputs = {{"cloud", DataType::Cloud, "the valid depth pixels back-projected, metres; camera frame, or world frame with 'studio'"},
                 {"grid", DataType::Cloud, "the same points organized as the image (width x height, NaN where no depth): for pcl.organized-fast-mesh"}};
    s.frame_ordered = true;  // .oni recordings: read forwards by one reader (see keeps_state)
    r.add(s, [](const Params& p) { return std::make_unique<ReadDepth>(p); });
  }
  {
    StageInfo s{"read-markers", "motion capture (C3D or TRC): per frame, the positions of the markers seen in that frame as a cloud"};
    s.params = {ParamSpec::input_path("path", "the .c3d or .trc file; frame k is its k-th frame (from 0)", true),
                ParamSpec::boolean("metres", true, "convert the file's units (mm, cm, m) to metres")};
    s.outputs = {{"cloud", DataType::Cloud, "the markers seen in this frame, in marker order (gaps left out)"}};
    r.add(s, [](const Params& p) { return std::make_unique<ReadMarkers>(p); });
  }
  {
    StageInfo s{"write-mesh", "writes the mesh of each frame (.ply .obj .off .vtk); files appear only when the whole run succeeded"};
    s.params = {ParamSpec::output_path("path", "output file; a %04d pattern names one file per frame"),
                ParamSpec::boolean("binary", true, "binary PLY (false: ASCII)")};
    s.inputs = {{"mesh", DataType::Mesh, "the mesh to write"}};
    r.add(s, [](const Params& p) { return std::make_unique<WriteMesh>(p); });
  }
  {
    StageInfo s{"write-cloud", "writes the cloud of each frame (.pcd .ply); files appear only when the whole run succeeded"};
    s.params = {ParamSpec::output_path("path", "output file; a %04d pattern names one file per frame"),
                ParamSpec::boolean("binary", true, "binary PCD/PLY (false: ASCII)")};
    s.inputs = {{"cloud", DataType::Cloud, "the cloud to write (normals written when it has them)"}};
    r.add(s, [](const Params& p) { return std::make_unique<WriteCloud>(p); });
  }
  {
    StageInfo s{"render-png", "renders the mesh of each frame (and optionally a cloud as dots) to a PNG"};
    s.params = {ParamSpec::output_path("path", "PNG file; a %04d pattern names one file per frame"),
                ParamSpec::real("azimuth", "30", "view azimuth, degrees", -360, 360),
                ParamSpec::real("elevation", "20", "view elevation, degrees", -90, 90),
                ParamSpec::integer("size", "480", "image width and height, pixels", 16, 4096)};
    s.inputs = {{"mesh", DataType::Mesh, "the mesh to draw"}, {"cloud", DataType::Cloud, "points drawn as dots", true}};
    r.add(s, [](const Params& p) { return std::make_unique<RenderPng>(p); });
  }
}

}  // namespace tbsp::pipeline::builtin
