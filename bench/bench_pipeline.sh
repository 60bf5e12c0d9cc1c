#!/usr/bin/env bash
# Pipeline scaling benchmark (docs/scaling.md): a synthetic range-scan replay (tbsp synth-studio
# --range-scans) through merge + voxel filter + per-frame template fit (no warm start, so frames
# are independent; tests/pipeline/replay_fit.yaml.in) on 1 process, 2 frame threads and mpirun -np 2. Prints frames/s, speed-up and
# efficiency, the per-frame compute and gather times, and the modelled time for 8 and 64 ranks.
#   bench/bench_pipeline.sh [build/plugins/tbsp] [FRAMES=100] [REPEATS=3]
set -euo pipefail
tbsp=$(realpath "${1:-build/plugins/tbsp}")
template=$(realpath "$(dirname "$0")/../tests/pipeline/replay_fit.yaml.in")
frames=${2:-100}
repeats=${3:-3}
mpiexec=$(command -v mpiexec || command -v mpirun || true)
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
"$tbsp" synth-studio --out studio --frames "$frames" --cameras 2 --width 192 --height 192 --range-scans -q
sed "s#@OUT@#out#g; s#@WARM@#false#g" "$template" > p.yaml
field() { sed -n "s/^  \"$1\": \([0-9.e+-]*\),\{0,1\}$/\1/p" out/report.json; }  # a top-level number of the report
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
run() {  # $1 = label, rest = command; prints the median wall time of $repeats runs
  local label=$1; shift
  local ts=()
  for _ in $(seq "$repeats"); do
    rm -rf out
    local s e
    s=$(date +%s.%N)
    "$@" > /dev/null
    e=$(date +%s.%N)
    ts+=("$(awk -v a="$s" -v b="$e" 'BEGIN { print b - a }')")
  done
  printf '%s\n' "${ts[@]}" | median
}
t1=$(run one "$tbsp" run -q --threads 1 p.yaml)
frame_s=$(awk '/^      "seconds": / { gsub(",", "", $2); s += $2; n++ } END { print s / n }' out/report.json)  # per-frame seconds
tt=$(run threads "$tbsp" run -q --threads 2 p.yaml)
echo "| run | wall s (median of $repeats) | frames/s | speed-up | efficiency |"
echo "|---|---:|---:|---:|---:|"
row() { awk -v l="$1" -v t="$2" -v t1="$t1" -v n="$3" -v f="$frames" 'BEGIN { printf "| %s | %.2f | %.2f | %.2f | %.0f %% |\n", l, t, f / t, t1 / t, 100 * t1 / t / n }'; }
row "1 process, 1 frame thread" "$t1" 1
row "1 process, 2 frame threads" "$tt" 2
if [ -n "$mpiexec" ]; then
  tm=$(run mpi "$mpiexec" -np 2 --oversubscribe "$tbsp" run -q p.yaml)
  row "mpirun -np 2" "$tm" 2
  gather=$(field gather_seconds)
  bytes=$(field gathered_bytes)
  r0=$(field rank0_compute_seconds)
  startup=$(run startup "$mpiexec" -np 2 --oversubscribe "$tbsp" run -q --check p.yaml)
  echo
  echo "per frame: compute $frame_s s (1 process); gather on rank 0: $gather s for $bytes bytes from rank 1;"
  echo "rank 0 compute $r0 s; mpirun start-up + plugin loading (tbsp run --check): $startup s"
  # model: T(N) = start-up + ceil(F/N) * t_frame + (F - F/N) * t_gather_per_frame (rank 0 receives serially)
  awk -v s="$startup" -v tf="$frame_s" -v g="$gather" -v f="$frames" -v sent="$(( frames / 2 ))" 'BEGIN {
    gpf = g / sent
    printf "\nmodel T(N) = start-up + ceil(F/N) t_frame + (F - F/N) t_gather, t_gather = %.4f s per frame\n\n", gpf
    print "| ranks | modelled wall s (F = " f ") | frames/s | efficiency |"
    print "|---:|---:|---:|---:|"
    for (n = 1; n <= 64; n *= 2) {
      if (n != 1 && n != 2 && n != 8 && n != 64) continue
      per = int((f + n - 1) / n)
      t = s + per * tf + (n > 1 ? (f - f / n) * gpf : 0)
      t1 = s + f * tf
      printf "| %d | %.2f | %.1f | %.0f %% |\n", n, t, f / t, 100 * t1 / t / n
    }
  }'
fi
