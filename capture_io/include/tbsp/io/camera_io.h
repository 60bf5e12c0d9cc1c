#pragma once
/// \file camera_io.h
/// \brief Camera calibration importers and exporters: Middlebury multi-view (`*_par.txt`),
/// COLMAP text models (`cameras.txt` + `images.txt`), plain 3x4 projection-matrix files.
/// All readers throw tbsp::FileError naming the file, the line and the fix on malformed input,
/// and validate every camera (finite values, rank-3 P, rotation) through tbsp::Camera.

#include <string>
#include <vector>

#include "tbsp/multiview/camera.h"

namespace tbsp {

/// Middlebury multi-view stereo parameters (Seitz et al. 2006): first line N, then N lines
/// `name.png k11..k33 r11..r33 t1 t2 t3` with P = K [R | t]. The file has no image size:
/// pass width/height, or leave them 0 to read the size of the first image next to the file
/// (FileError naming the image when it is missing). Camera names are the image file names.
std::vector<Camera> read_middlebury_par(const std::string& path, int width = 0, int height = 0);
/// Writes the Middlebury format (distortion is not representable: InvalidInput if present).
void write_middlebury_par(const std::string& path, const std::vector<Camera>& cameras);

/// COLMAP text model in `dir` (cameras.txt + images.txt; points3D.txt is not needed).
/// Supported camera models: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV; other
/// models give FileError naming the model. COLMAP puts the centre of the top-left pixel at
/// (0.5, 0.5); tbsp at (0, 0): principal points are shifted by -0.5 on import (+0.5 on
/// export). Cameras are returned in images.txt order, named by the image name.
std::vector<Camera> read_colmap_text(const std::string& dir);
/// Writes cameras.txt + images.txt (one OPENCV or PINHOLE camera per image, no 2D points).
void write_colmap_text(const std::string& dir, const std::vector<Camera>& cameras);

/// Calibration of a rectified stereo pair in the Middlebury 2014 `calib.txt` format:
/// `cam0=[f 0 cx0; 0 f cy; 0 0 1]`, `cam1=[f 0 cx1; 0 f cy; 0 0 1]`, `doffs=` (cx1 - cx0),
/// `baseline=` (world units, mm in Middlebury), optional `width=`, `height=`, `ndisp=`, `vmin=`,
/// `vmax=`, `isint=`, `dyavg=`, `dymax=` (read and ignored where unused). Depth of a left pixel
/// with disparity d: Z = baseline * f / (d + doffs).
struct RectifiedPairCalibration {
  double f = 0;             ///< focal length, pixels (both cameras)
  double cx0 = 0, cx1 = 0;  ///< principal points' x, pixels
  double cy = 0;            ///< common principal point y, pixels
  double doffs = 0;         ///< cx1 - cx0
  double baseline = 0;      ///< world units
  int width = 0, height = 0, ndisp = 0;  ///< 0 when absent
};
/// Throws FileError ("FILE:LINE: ...") on a missing file, unknown or repeated keys, matrices that
/// are not 3x3 numbers, f <= 0, two different focal lengths or cy, doffs inconsistent with the
/// principal points (|doffs - (cx1 - cx0)| > 0.01 px), baseline <= 0, or missing cam0/cam1/baseline.
RectifiedPairCalibration read_middlebury_stereo_calib(const std::string& path);

/// A plain 3x4 projection matrix: 12 numbers, row-major, in pixels. Accepted around them:
/// '#' comments, an XML `<camera>...</camera>` wrapper (as in the INRIA "dancer" set) and a
/// leading `CONTOUR` keyword (as in MIT's `.Pmat.cal` files). Anything else is an error.
Camera read_projection_matrix(const std::string& path, int width, int height, const std::string& name = "");
void write_projection_matrix(const std::string& path, const Camera& camera);

/// The Tsinghua dome calibration (`calibParamsI.txt` of the WD2 / lkB sets, 20 cameras): blocks
/// of the camera index (an integer), K (3 rows of 3, with skew), two radial distortion
/// coefficients k1 k2 (OpenCV's model on normalised coordinates) and [R | t] (3 rows of 4,
/// world -> camera). Cameras are named "cam<index>". The file holds no image size: pass it
/// (1024 x 768 for WD2 / lkB). Throws FileError ("FILE:LINE: ...") on a missing file, a
/// missing or non-numeric entry, a repeated index, no camera, a non-rotation R or a bad K.
std::vector<Camera> read_dome_calibration(const std::string& path, int width, int height);

}  // namespace tbsp
