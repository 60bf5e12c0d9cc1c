#pragma once
// Helpers of the studio commands (stereo, refine-*, capture): frame ranges, streaming with a
// progress bar, atomic PNG writes.
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "progress_bar.h"
#include "tbsp/core/progress.h"
#include "tbsp/io/studio.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::cli {

/// "--frames a:b" or "a" (the studio's frame numbers, inclusive); empty = all. InvalidInput when
/// malformed or outside the studio, naming `option` (the command's own option name).
std::pair<int, int> parse_frames(const std::string& s, const Studio& st, const std::string& option = "--frames");

// Streams frames first..last of a studio with a progress bar over all of them: `run(frame,
// progress)` gets each frame and a callback mapping its own [0, 1] into the frame's share.
// Returns the number of frames run.
int for_each_frame(const Studio& st, int first, int last, bool silhouettes, bool quiet,
                   const std::function<void(const StudioFrame&, const ProgressCallback&, ProgressBar&)>& run);

/// All views of one frame in a grid (4 columns), each cropped to the performer: where the mesh
/// and the silhouette agree the camera image is tinted green; mesh outside the silhouette is
/// blue, silhouette the mesh misses is red. `fr` needs silhouettes (images optional).
cv::Mat overlay_grid(const TriMesh& mesh, const std::vector<Camera>& cams, const StudioFrame& fr);

/// Writes an image atomically (temporary file + rename); PNG by the path's extension.
void write_png(const std::string& path, const cv::Mat& m);

}  // namespace tbsp::cli
