#pragma once
/// \file mocap_io.h
/// \brief Motion-capture readers: marker trajectories (TRC, C3D) and skeletons with motion
/// (BVH). Malformed files throw tbsp::FileError naming the file and the line (text) or byte
/// offset (binary) and what to do.

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tbsp {

/// Marker trajectories: frames x markers positions, NaN where a marker is missing (gaps).
struct MarkerTrajectories {
  std::vector<std::string> names;  ///< one per marker
  double frame_rate = 0;           ///< Hz
  int first_frame = 1;             ///< number of the first frame in the source
  std::string units;               ///< as given by the file ("mm", "m", ...)
  Eigen::MatrixXd data;            ///< numFrames() x 3*numMarkers(): x y z per marker
  int analog_per_frame = 0;        ///< C3D: analog samples per frame (channels x sub-samples); not read

  int numFrames() const { return static_cast<int>(data.rows()); }
  int numMarkers() const { return static_cast<int>(names.size()); }
  Eigen::Vector3d position(int frame, int marker) const { return data.block<1, 3>(frame, 3 * marker).transpose(); }
  bool valid(int frame, int marker) const { return data.block<1, 3>(frame, 3 * marker).allFinite(); }
  /// Index of a marker by name, -1 when absent.
  int markerIndex(const std::string& name) const;
};

/// OpenSim / Motion Analysis TRC (PathFileType 4, (X/Y/Z)). Empty cells are gaps (NaN).
/// Rows without a frame number (spreadsheet residue after the data) are ignored with a warning.
MarkerTrajectories read_trc(const std::string& path);
/// Writes TRC (tab-separated, atomic). Gaps are written as empty cells.
void write_trc(const std::string& path, const MarkerTrajectories& markers);

/// C3D (c3d.org): Intel processor type, float (SCALE < 0) or 16-bit integer point data.
/// DEC (VAX) and MIPS (big-endian) files give a FileError naming the processor type. Points
/// with a negative residual are gaps (NaN). Labels from POINT:LABELS (+ LABELS2..), rate and
/// units from the POINT group, frame count from the header (or POINT:FRAMES when larger).
/// A data section shorter than the declared frame count is a FileError ("truncated"), unless
/// `allow_truncated`: then the complete frames present are returned and a warning is logged.
MarkerTrajectories read_c3d(const std::string& path, bool allow_truncated = false);

/// read_c3d or read_trc by the file's extension (.c3d / .trc, any case).
/// \throws InvalidInput naming the file for any other extension.
MarkerTrajectories read_markers(const std::string& path);

/// Metres per unit of a marker file's `units` ("mm", "cm", "m"). \throws InvalidInput for
/// other units (the message says which).
double marker_units_to_metres(const std::string& units);

/// Writes C3D (Intel processor type, float point data, written atomically) that read_c3d and
/// other C3D tools read back: POINT:USED/SCALE/RATE/DATA_START/FRAMES/UNITS/LABELS(2..) and an
/// empty ANALOG group. Gaps (NaN) are written with residual -1. Frame numbers start at
/// max(1, first_frame). Throws InvalidInput when the data do not fit C3D: no markers or frames,
/// more than 65535 frames or markers, names over 255 characters, |coordinate| > 3e38.
void write_c3d(const std::string& path, const MarkerTrajectories& markers);

/// One BVH joint (End Sites are joints with no channels and end_site = true).
struct BvhJoint {
  enum Channel { Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation };
  std::string name;
  int parent = -1;
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  std::vector<Channel> channels;
  int first_channel = 0;  ///< column of its first channel in BvhMotion::motion
  bool end_site = false;
};

/// A BVH skeleton with its motion. Rotation channels are in degrees and compose in the order
/// listed (M = T · R_c1 · R_c2 · R_c3, column vectors), as in the BVH convention.
struct BvhMotion {
  std::vector<BvhJoint> joints;  ///< parents before children (file order)
  double frame_time = 0;         ///< seconds
  Eigen::MatrixXd motion;        ///< frames x channels

  int numFrames() const { return static_cast<int>(motion.rows()); }
  int numChannels() const { return static_cast<int>(motion.cols()); }
  /// ROOT + JOINT count (End Sites excluded), the number usually quoted for a BVH file.
  int numJoints() const;
  /// Global transforms of all joints (End Sites included) at a frame. O(#joints).
  std::vector<Eigen::Isometry3d> globalTransforms(int frame) const;
  /// Global joint positions (rows follow `joints`).
  Eigen::MatrixX3d jointPositions(int frame) const;
};

BvhMotion read_bvh(const std::string& path);
void write_bvh(const std::string& path, const BvhMotion& motion);

}  // namespace tbsp
