#!/usr/bin/env bash
# Installs the built tree into a temporary prefix and builds a small consumer project with
# find_package(tbsp), then runs it: the exported CMake package works for users.
set -euo pipefail
build_dir=$1; src_dir=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build_dir" --prefix "$work/prefix" > "$work/install.log"
cmake -S "$src_dir" -B "$work/b" -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/configure.log" 2>&1 || { cat "$work/configure.log"; exit 1; }
cmake --build "$work/b" -j2 > "$work/build.log" 2>&1 || { cat "$work/build.log"; exit 1; }
out=$("$work/b/c")
echo "consumer printed: $out"
# the deformed vertex 0 must sit at its target (0, 0, 2)
echo "$out" | awk '{ if ($3 < 1.999 || $3 > 2.001) exit 1 }'
