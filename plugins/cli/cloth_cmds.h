#pragma once
// `tbsp cloth ...` (thesis ch. 10, docs/cloth.md): shared pieces of the cloth sub-commands.
#include <CLI/CLI.hpp>

#include <string>
#include <vector>

#include "command.h"
#include "tbsp/cloth/skeleton.h"
#include "tbsp/io/mocap_io.h"
#include "tbsp/mesh/tri_mesh.h"

namespace tbsp::cli {

/// The mesh files of a folder (.ply, .obj, .off), sorted by name. \throws FileError when the
/// folder does not exist or holds none.
std::vector<std::string> mesh_files_in(const std::string& dir);

/// The pose of `skeleton`'s joints taken by name from the clip's frame (scaled to metres).
/// \throws InvalidInput naming the clip and the joints it lacks.
SkeletonPose pose_by_name(const Skeleton& skeleton, const BvhMotion& clip, int frame, double scale, const std::string& clip_name);

/// Renders up to `count` frames (evenly spread over `meshes`) into a contact sheet PNG.
void write_contact_sheet(const std::string& path, const std::vector<TriMesh>& meshes, const std::vector<std::string>& titles);

void add_cloth_segment_commands(CLI::App& cloth, CommandTable& table);  // synth, segment
void add_cloth_model_commands(CLI::App& cloth, CommandTable& table);    // build, animate
void add_cloth_estimate_commands(CLI::App& cloth, CommandTable& table); // estimate

}  // namespace tbsp::cli
