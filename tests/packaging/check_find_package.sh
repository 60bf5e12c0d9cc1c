#!/usr/bin/env bash
# Installs the built tree into a temporary prefix and builds a small consumer project with
# find_package(tbsp), then runs it: the exported CMake package works for users. Also builds a
# PCL pipeline program (VoxelGrid -> TemplateFitting -> savePLYFile) and a third-party stage
# plugin against the installed package, and loads the plugin into the installed `tbsp`.
set -euo pipefail
build_dir=$1; src_dir=$2; sample=$3; with_ui=${4:-OFF}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" > "$work/install.log"
cmake -S "$src_dir" -B "$work/b" -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/configure.log" 2>&1 || { cat "$work/configure.log"; exit 1; }
cmake --build "$work/b" -j2 > "$work/build.log" 2>&1 || { cat "$work/build.log"; exit 1; }
out=$("$work/b/c")
echo "consumer printed: $out"
# the deformed vertex 0 must sit at its target (0, 0, 2)
echo "$out" | awk '{ if ($3 < 1.999 || $3 > 2.001) exit 1 }'
# the PCL pipeline program fits the sample bar scan (5 % outliers; a few survive the filter, so rms, not Hausdorff)
fit=$("$work/b/pipeline_example" "$sample/bar_scan.ply" "$sample/bumpy_bar.off" "$sample/bar_markers.json" "$work/fit.ply")
echo "pipeline_example printed: $fit"
echo "$fit" | awk '{ if ($10 > 0.01) exit 1 }'  # rms / bbox diagonal, measured 0.0041
test -s "$work/fit.ply"
# the installed tbsp finds its built-in stages in <prefix>/lib/tbsp/plugins and loads the plugin
stages=$(env -u TBSP_PLUGIN_PATH "$work/prefix/bin/tbsp" plugins --plugin "$work/b/libsample_plugin.so")
echo "$stages" | grep -q "^sample.scale  \[libsample_plugin.so\]"
echo "$stages" | grep -q "^pcl.voxel-grid  \[libtbsp_stages.so\]"
ls "$work"/prefix/lib*/tbsp/plugins/libtbsp_stages.so > /dev/null
echo "installed tbsp lists $(echo "$stages" | grep -c '^[a-z]') stages, the sample plugin's among them"
# tbsp::Visualizer (libtbsp_vtk) from the installed package: a PCL cloud + heatmap, offscreen
if [ "$with_ui" = ON ]; then
  test -x "$work/b/viz_example" || { echo "viz_example was not built: tbsp::vtk missing from the installed package"; exit 1; }
  viz=$(xvfb-run -a -s "-screen 0 1280x1024x24" "$work/b/viz_example" "$sample/bar_scan.ply" "$work/fit.ply" "$work/viz.png")
  echo "viz_example printed: $viz"
  test -s "$work/viz.png"
fi
