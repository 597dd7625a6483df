#!/bin/bash
# Every issue-20 benchmark in one go, on a quiet machine (benchmarks/README.md records a run of it).
# Uses a throw-away cache directory so the README main job starts cold.
cd "$(dirname "$0")/.."
export XDG_CACHE_HOME="${TMPDIR:-/tmp}/appearance-jax-bench-xdg"
rm -rf "${TMPDIR:-/tmp}/appearance-jax-bench-xdg" "${TMPDIR:-/tmp}/appearance-jax-bench-out"; mkdir -p "${TMPDIR:-/tmp}/appearance-jax-bench-out"
echo "=== README main job: cold then warm (fresh cache) $(date)"
for i in cold warm warm2; do
  /usr/bin/time -f "$i %e s wall, %M KB maxrss" appearance-jax fit data/tables/merl-proxy-red-fabric-in-plane.csv --model rough_plastic --fix eta=1.5 --loss cos_log --out "${TMPDIR:-/tmp}/appearance-jax-bench-out"/main_$i 2>&1 | grep -E "wall|fitted with|status"
done
echo "=== same with --no-compile-cache"
/usr/bin/time -f "nocache %e s wall" appearance-jax fit data/tables/merl-proxy-red-fabric-in-plane.csv --model rough_plastic --fix eta=1.5 --loss cos_log --out "${TMPDIR:-/tmp}/appearance-jax-bench-out"/main_nc --no-compile-cache 2>&1 | grep -E "wall|fitted with"
echo "=== fit_lm_vs_powell --processes $(date)"
python3 benchmarks/fit_lm_vs_powell.py --processes
echo "=== fit_lm_vs_powell in-process $(date)"
APPEARANCE_JAX_COMPILE_CACHE=off python3 benchmarks/fit_lm_vs_powell.py
echo "=== solver_compile $(date)"
python3 benchmarks/solver_compile.py
echo "=== compile_times $(date)"
python3 benchmarks/compile_times.py
echo "=== compile_times x64 fitter-relevant $(date)"
python3 benchmarks/compile_times.py --x64 --models rough_conductor,rough_plastic,rough_dielectric,lambert,rough_conductor+lambert
echo "=== bsdf_throughput $(date)"
python3 benchmarks/bsdf_throughput.py --repeats 10 --native
echo "=== plastic_throughput $(date)"
python3 benchmarks/plastic_throughput.py --repeats 10
echo "=== dielectric_throughput $(date)"
python3 benchmarks/dielectric_throughput.py --repeats 10 --before
echo "=== hair_throughput $(date)"
python3 benchmarks/hair_throughput.py --repeats 5
echo "=== done $(date)"
