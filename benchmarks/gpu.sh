#!/usr/bin/env bash
# Issue #36 part 4, "The GPU": every GPU measurement in one run of at most ~8.5 minutes.
#
#   bash benchmarks/gpu.sh            (on the device machine: $OUT is its output folder)
#   JAX_PLATFORMS=cpu QUICK=1 OUT=/tmp/o bash benchmarks/gpu.sh   (a dry run on a CPU:
#                                      every step, on small work)
#
# It installs the carried wheels (.whl/: pydantic and its needs, evosax and dotmap; the
# image lacks them) into /tmp/site, prints the GPU and JAX, then runs, each under its
# own time cap and all under one deadline (BUDGET seconds, default 510), most important
# first:
#   1. benchmarks/hlo_step.py: kernels and conditionals per PSO iteration (PTPSO with the
#      GPU's step and with the CPU's, p2, evosax) from the compiled HLO
#   2. benchmarks/pso_throughput.py: PTPSO vs evosax (100 runs × 1000 iterations), with a
#      row for PTPSO compiled with the CPU's step (its two conditionals)
#   3. benchmarks/main_job.py on the GPU (cold and warm, 2 repeats) and 4. the same on
#      this machine's CPU (JAX_PLATFORMS=cpu)
#   5. the main job on the GPU with the objective fused into the runner's scan
#   6. one cold main job with XLA's GPU autotuning off (--xla_gpu_autotune_level=0)
#   7. one cold main job logging every compilation (JAX_LOG_COMPILES): compile-log.txt
#   8. benchmarks/ik.py --only generic, 9. benchmarks/latency.py on two commands
# and first of all 0. benchmarks/planning_profile.py: the planning case's task block program
# (collision-free solves per second), on the GPU and on the machine's CPU. STEPS=planning,hlo
# runs only the steps named.
# Everything printed goes to $OUT/gpu.log (and stdout); the HLO texts to $OUT/hlo.tar.gz.
set -u -o pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/designopt-gpu-out}
mkdir -p "$OUT"
LOG=$OUT/gpu.log
BUDGET=${BUDGET:-510}
: >"$LOG"
say() { echo "$*" | tee -a "$LOG"; }

# (a) the carried wheels; the repo itself is not installed: it runs from here
if ls .whl/*.whl >/dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl 2>&1 | tee -a "$LOG" || { say "wheel install failed"; exit 1; }
    export PYTHONPATH=/tmp/site:$PWD
else
    say "no .whl/ here: using the packages this python3 has"
    export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONUNBUFFERED=1

# (b, c) what runs where
say "== $(date -u +%FT%TZ) $(hostname) $(nproc) CPU cores, $(uname -m)"
if command -v nvidia-smi >/dev/null; then
    nvidia-smi -L 2>&1 | tee -a "$LOG"
    nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>&1 \
        | tee -a "$LOG"
else
    say "no nvidia-smi here"
fi
python3 - <<'EOF' 2>&1 | tee -a "$LOG" || { say "designopt does not import"; exit 1; }
import importlib.metadata as md, sys
import jax, jaxlib
print("python", sys.version.split()[0], "| jax", jax.__version__, "jaxlib", jaxlib.__version__,
      "| backend", jax.default_backend(), "| devices", jax.devices())
for m in ("numpy", "pydantic", "pydantic_core", "evosax", "dotmap", "flax", "optax", "h5py",
          "matplotlib", "scipy"):
    try:
        print(f"  {m} {md.version(m)}")
    except md.PackageNotFoundError:
        print(f"  {m}: NOT INSTALLED")
try:
    import evosax.algorithms  # noqa: F401 - pso_throughput's peer (skipped if it fails)
except Exception as e:  # noqa: BLE001 - report and go on
    print(f"  evosax does not import: {type(e).__name__}: {e}")
import designopt, designopt.cli  # noqa: F401,E401 - without these nothing runs
print("  designopt from", designopt.__file__)
EOF
python3 -m designopt --help >/dev/null 2>&1 && say "python3 -m designopt: runs" \
    || say "python3 -m designopt: FAILS"

# (d) the measurements, each capped; none starts with less than 20 s of the budget left
step() {  # step NAME CAP command...: run it under min(CAP, time left), output to the log
    local name=$1 cap=$2
    shift 2
    if [ -n "${STEPS:-}" ] && [[ ",$STEPS," != *",$name,"* ]]; then
        return  # STEPS=a,b: only the steps named
    fi
    local left=$((BUDGET - SECONDS))
    if ((left < 20)); then
        say "== $name: skipped ($left s of the budget left)"
        return
    fi
    ((cap > left)) && cap=$left
    say "== $name (cap ${cap} s, at ${SECONDS} s): $*"
    local t0=$SECONDS
    timeout -k 5 "$cap" "$@" 2>&1 | tee -a "$LOG"
    local rc=${PIPESTATUS[0]}
    say "== $name: rc=$rc after $((SECONDS - t0)) s"
}

if [ -n "${QUICK:-}" ]; then  # the dry run: the same steps on small work
    HLO=(--iters 20) PSO=(--runs 4 --iters 50 --repeat 1) REP=1
    IK=(--generic 256 --repeat 1) LAT=(--only puma560-eval)
else
    HLO=() PSO=(--repeat 5) REP=2 IK=(--repeat 3) LAT=(--only planar2r --only puma560-eval)
fi
step planning 150 python3 benchmarks/planning_profile.py --repeat "$REP"
step planning-cpu 150 env JAX_PLATFORMS=cpu python3 benchmarks/planning_profile.py --repeat "$REP"
step hlo 90 python3 benchmarks/hlo_step.py "${HLO[@]}" --detail --dump "$OUT/hlo"
step hlo-cpu-step 45 python3 benchmarks/hlo_step.py "${HLO[@]}" --only ptpso \
    --formulation cpu --dump "$OUT/hlo"
step pso-throughput 120 python3 benchmarks/pso_throughput.py "${PSO[@]}" --pyswarms-runs 0 \
    --formulations
step main-job-gpu 110 python3 benchmarks/main_job.py --repeat "$REP" --no-report
step main-job-cpu 100 env JAX_PLATFORMS=cpu python3 benchmarks/main_job.py --repeat "$REP" \
    --no-report
step main-job-gpu-fused 60 python3 benchmarks/main_job.py --repeat 1 --no-report \
    --set optimizer.objective_program=fused
step main-job-gpu-autotune0 40 env XLA_FLAGS="${XLA_FLAGS:-} --xla_gpu_autotune_level=0" \
    python3 benchmarks/main_job.py --repeat 1 --no-report
CACHE=$(mktemp -d)
CLOG=$OUT/compile-log.txt
step compile-log 40 env DESIGNOPT_CACHE_DIR="$CACHE" JAX_LOG_COMPILES=1 \
    bash -c 'python3 -m designopt run configs/master9.yaml --out "$0/m9.h5" --quiet \
             --no-figures >"$1" 2>&1; tail -3 "$1"' "$CACHE" "$CLOG"
if [ -s "$CLOG" ]; then  # the slowest XLA compilations of that cold run, slowest last
    say "   slowest XLA compilations (of $(grep -c 'Finished XLA compilation' "$CLOG")):"
    grep -o 'Finished XLA compilation of .* sec' "$CLOG" | awk '{print $(NF-1), $5}' \
        | sort -g | tail -12 | tee -a "$LOG"
fi
rm -rf "$CACHE"
step ik-generic 90 python3 benchmarks/ik.py --only generic "${IK[@]}"
step latency 60 python3 benchmarks/latency.py "${LAT[@]}"

[ -d "$OUT/hlo" ] && tar -czf "$OUT/hlo.tar.gz" -C "$OUT" hlo && rm -rf "$OUT/hlo"
say "== done at ${SECONDS} s; files: $(ls "$OUT" | tr '\n' ' ')"
