#!/usr/bin/env bash
# `tbsp cloth estimate` under mpirun -np 2 (ctest label mpi): the estimate, the report's samples
# and energies and the landscape bit-identical to the one-process run; a bad input on every rank,
# and a frame only rank 1 reads that cannot be decoded -> one message from rank 0 (naming rank 1
# in the second case), exit 2, no hang, no output folder.
#   check_cloth_mpi.sh TBSP MPIEXEC SHARED_DATA_DIR
set -euo pipefail
tbsp=$1; mpiexec=$2; shared=$3
clip=$shared/capture/dopomoc__BVH/02_05.bvh
[ -f "$clip" ] || { echo "skipped: $clip not found"; exit 77; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1  # CI runs as root
export OMPI_MCA_rmaps_base_oversubscribe=1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
"$tbsp" cloth synth --bvh "$clip" --frames 16 --studio-views 4 --studio-size 240 --contact-sheet 0 --out seq -q
"$tbsp" cloth segment --frames seq --out seg.json -q
"$tbsp" cloth build --template seq/mesh_0000.ply --bvh "$clip" --segmentation seg.json --out model.json -q
estimate() {  # $1 = output folder, then the launcher prefix
  local out=$1; shift
  "$@" "$tbsp" cloth estimate --model model.json --studio seq/studio/studio.yaml --bvh "$clip" --reference seq --start-samples 4 \
    --max-evaluations 8 --landscape 2 --truth 2,4,0.3 --out "$out" -q
}
estimate one
estimate two timeout 300 "$mpiexec" -np 2 --oversubscribe
cmp one/estimated_model.json two/estimated_model.json
cmp one/landscape.png two/landscape.png
# the reports differ only in the timings and the process count
same() { grep -v -e '"seconds"' -e '"observation_seconds"' -e '"processes"' "$1"; }
diff <(same one/estimate_report.json) <(same two/estimate_report.json)
grep -q '"processes": 1' one/estimate_report.json
grep -q '"processes": 2' two/estimate_report.json
echo "mpirun -np 2: estimate, report and landscape bit-identical to the one-process run"

# an estimate under mpirun -np 2 that must fail with exit 2 (no hang): $1 = its stderr file, then
# the estimate's own arguments
fails() {
  local err=$1; shift
  set +e
  timeout 120 "$mpiexec" -np 2 --oversubscribe "$tbsp" cloth estimate --model model.json --bvh "$clip" -q "$@" 2> "$err"
  rc=$?
  set -e
  cat "$err"
  [ "$rc" -eq 2 ] || { echo "expected exit 2, got $rc"; exit 1; }
}

# a reference with fewer meshes than frames: the same error on both ranks, printed once
mkdir short && cp seq/mesh_0000.ply short/
fails err.txt --studio seq/studio/studio.yaml --reference short --out bad
[ "$(grep -c '1 meshes for the studio' err.txt)" -eq 1 ] || { echo "expected the message once"; exit 1; }
[ ! -e bad ] || { echo "an output folder was written"; exit 1; }
echo "a bad input under mpirun: exit $rc, one message, nothing written"

# one rank fails alone: rank 1 observes frames 8-15, and one of its images cannot be decoded;
# rank 0 read its own frames without fault, learns of the error at the ranks' agreement and
# prints it once, naming rank 1; nothing is written
cp -r seq/studio broken
printf 'not a PNG' > broken/images/cam0/0015.png
fails err1.txt --studio broken/studio.yaml --reference seq --out bad1
[ "$(grep -c 'cannot be decoded' err1.txt)" -eq 1 ] || { echo "expected the message once"; exit 1; }
grep -q '(rank 1 of 2)' err1.txt || { echo "expected the message to name rank 1"; exit 1; }
grep -q "0015.png" err1.txt || { echo "expected the message to name the file"; exit 1; }
[ ! -e bad1 ] || { echo "an output folder was written"; exit 1; }
echo "a frame only rank 1 reads is broken: exit $rc, one message naming rank 1 and the file, nothing written"
