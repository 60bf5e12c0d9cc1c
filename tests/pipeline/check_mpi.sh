#!/usr/bin/env bash
# `tbsp run` under mpirun -np 2 (ctest label mpi): outputs bit-identical to the one-process run,
# a failing frame on one rank -> its message (rank, frame, node, line), exit 2, no hang and the
# earlier outputs untouched; a pipeline that keeps state across frames is refused.
#   check_mpi.sh TBSP MPIEXEC
set -euo pipefail
tbsp=$1; mpiexec=$2
template=$(realpath "$(dirname "$0")/replay_fit.yaml.in")
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1  # CI runs as root
export OMPI_MCA_rmaps_base_oversubscribe=1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
"$tbsp" synth-studio --out studio --frames 6 --cameras 2 --width 160 --height 160 --range-scans -q
write_pipeline() {  # $1 = output folder, $2 = warm_start
  sed "s#@OUT@#$1#g; s#@WARM@#$2#g" "$template" > "p_$1.yaml"
}
write_pipeline one false
write_pipeline two false
write_pipeline warm true
"$tbsp" run -q --threads 1 p_one.yaml
"$mpiexec" -np 2 --oversubscribe "$tbsp" run -q p_two.yaml
n=0
for f in one/fit_*.ply one/cloud_*.pcd; do
  cmp "$f" "two/$(basename "$f")"
  n=$((n + 1))
done
[ "$n" -eq 12 ] || { echo "expected 12 outputs, compared $n"; exit 1; }
grep -q '"ranks": 2' two/report.json
echo "mpirun -np 2: $n outputs bit-identical to the one-process run"

# frame 3 is frame list position 3 -> rank 1; corrupt it: rank 1 fails, rank 0 stops, nothing written
cp two/fit_0000.ply before.ply
echo "not a pcd" > studio/scans/cam1/0003.pcd
sed -i 's/leaf: 0.02/leaf: 0.03/' p_two.yaml
set +e
timeout 120 "$mpiexec" -np 2 --oversubscribe "$tbsp" run -q p_two.yaml 2> err.txt
rc=$?
set -e
cat err.txt
[ "$rc" -eq 2 ] || { echo "expected exit 2 from the failing run, got $rc"; exit 1; }
grep -q "error (rank 1 of 2): frame 3, node 'cam1' (read-cloud, p_two.yaml:7)" err.txt
cmp before.ply two/fit_0000.ply  # the earlier output is untouched
if ls -a two | grep -q "tbsp-run"; then echo "temporary files left behind"; exit 1; fi
echo "a failing frame on rank 1: exit $rc, message names rank, frame, node and line, earlier outputs kept"

set +e
"$mpiexec" -np 2 --oversubscribe "$tbsp" run -q p_warm.yaml 2> err2.txt
rc=$?
set -e
[ "$rc" -eq 2 ] || { echo "expected exit 2 for a warm-started pipeline under mpirun, got $rc"; cat err2.txt; exit 1; }
grep -q "keeps state from frame to frame" err2.txt
echo "a warm-started pipeline under mpirun is refused with exit 2"
