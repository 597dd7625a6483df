#!/bin/bash
# The issue-20 benchmarks on a GPU machine (benchmarks/README.md, "GPU"), JAX's default backend
# being the GPU: our models on the GPU against Mitsuba 3's cuda_ad_rgb; miepython, tmm and SciPy
# stay CPU programs (their figures are the CPU peer's). Every step has its own time limit so one
# slow step cannot take the others' time. Needs mitsuba/drjit importable (see the README) and
# appearance-jax installed.
cd "$(dirname "$0")/.."
export APPEARANCE_JAX_BENCH_MITSUBA=cuda_ad_rgb PYTHONUNBUFFERED=1
export XDG_CACHE_HOME="${TMPDIR:-/tmp}/appearance-jax-gpu-xdg"; rm -rf "$XDG_CACHE_HOME"
OUTD="${TMPDIR:-/tmp}/appearance-jax-gpu-out"; rm -rf "$OUTD"; mkdir -p "$OUTD"
step() { local lim=$1; shift; echo "=== [$(date +%T), limit ${lim}s] $*"; timeout "$lim" "$@" 2>&1 | grep -v -E "Warning|warn\(" ; }
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv,noheader
python3 -c "import jax, jaxlib; print('jax', jax.__version__, jax.devices())"
step 70 python3 benchmarks/bsdf_throughput.py --n 16000000 --repeats 10 --devices 1 --native
step 60 python3 benchmarks/plastic_throughput.py --n 16000000 --repeats 10 --devices 1
step 60 python3 benchmarks/dielectric_throughput.py --n 16000000 --repeats 10 --devices 1 --before
step 60 python3 benchmarks/hair_throughput.py --n 4000000 --repeats 5 --devices 1
for i in cold warm; do
  step 60 /usr/bin/time -f "README main job $i: %e s wall" appearance-jax fit data/tables/merl-proxy-red-fabric-in-plane.csv \
    --model rough_plastic --fix eta=1.5 --loss cos_log --out "$OUTD/main_$i"
done
step 50 python3 benchmarks/cloth_throughput.py --n 1000000 --repeats 5 --devices 1
step 50 python3 benchmarks/rock_dove_throughput.py --n 262144 --repeats 3
step 40 python3 benchmarks/thinfilm_vs_tmm.py --n 1000000 --pairs 16000000 --repeats 5
step 100 python3 benchmarks/mie_vs_miepython.py --repeats 3
step 60 python3 benchmarks/fit_lm_vs_powell.py
step 240 python3 benchmarks/compile_times.py
echo "=== done $(date +%T)"
