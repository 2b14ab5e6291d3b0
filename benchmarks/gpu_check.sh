#!/usr/bin/env bash
# The one GPU check of warpworm (issue #12 goal 5): CUDA against the CPU on the same inputs, then the benchmark summary
# (worm-substeps/s at 1k, 16k, 64k worlds, images/s, samples/s) and a per-kernel profile, all written to $OUT.
#
# warp-lang is not on the GPU machine and nothing can be downloaded there: its wheel (149 MB) travels in three parts of
# 50 MB (a call carries at most 64 MiB). The machine keeps files only while warm (30 s after a call), so make the four
# calls BACK TO BACK, nothing in between:
#
#   here, once:   bash benchmarks/gpu_check.sh prepare           # .whl/warp.part-00 .. -02 (.whl/ is git-ignored)
#   device run 1: command "bash benchmarks/gpu_check.sh stage", carry [".whl/warp.part-00"], timeout_s 120
#   device run 2: command "bash benchmarks/gpu_check.sh stage", carry [".whl/warp.part-01"], timeout_s 120
#   device run 3: command "bash benchmarks/gpu_check.sh run",   carry [".whl/warp.part-02"], timeout_s 560
#
# 'run' refuses (exit 3, in seconds) when the parts of the earlier calls are gone (the machine went back between calls):
# start again from run 1. 'run' keeps itself within BUDGET_S (default 470 s) by giving each stage what is left, so
# the call ends inside 8 minutes; each stage's failure is logged and the next stage still runs.
# Back (at most 8 files): gpu_check.log (everything printed), nvidia-smi.txt, compile.json, cuda_vs_cpu.json,
# summary.json (benchmarks/run.py --device cuda), profile_cuda.json (benchmarks/profile_step.py --device cuda).
set -u
WHEEL=warp_lang-1.19.0-py3-none-manylinux_2_28_x86_64.whl
SHA256=c797f5f4aa9925f676e20dd28e5416fee794499f3f3c0a5b66f2d4dfc2de9e32
PARTS=/tmp/ww_parts
MODE=${1:-run}
cd "$(dirname "$0")/.."
REPO=$PWD

case "$MODE" in
prepare)
  mkdir -p .whl
  if [ ! -f ".whl/$WHEEL" ]; then
    python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
      --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
      -d .whl warp-lang==1.19.0 || exit 1
  fi
  echo "$SHA256  .whl/$WHEEL" | sha256sum -c - || exit 1
  rm -f .whl/warp.part-*
  split -b 50M -d -a 2 ".whl/$WHEEL" .whl/warp.part-
  ls -la .whl
  git check-ignore -q .whl/ || echo "WARNING: .whl/ is not ignored: it would travel with every call"
  exit 0 ;;
stage)
  mkdir -p "$PARTS"
  cp -v .whl/warp.part-* "$PARTS"/ && ls -la "$PARTS"
  exit 0 ;;
run) ;;
*) echo "usage: $0 prepare | stage | run" >&2; exit 2 ;;
esac

# ---------------------------------------------------------------------------------------------------------------- run
OUT=${OUT:-/tmp/ww_gpu_out}
mkdir -p "$OUT"
exec > >(tee -a "$OUT/gpu_check.log") 2>&1
export PYTHONUNBUFFERED=1
BUDGET_S=${BUDGET_S:-470}
T0=$(date +%s)
left() { echo $(( BUDGET_S - ($(date +%s) - T0) )); }
stage() {  # stage NAME MAX_SECONDS CMD...: run CMD under min(MAX, time left), log its status
  local name=$1 max=$2; shift 2
  local t=$(left); [ "$t" -gt "$max" ] && t=$max
  if [ "$t" -lt 10 ]; then echo "== $name: SKIPPED (budget spent)"; return 0; fi
  echo "== $name (limit ${t} s, $(( $(date +%s) - T0 )) s in) =="
  timeout -k 5 "$t" "$@"; local rc=$?
  echo "== $name: rc=$rc ($(( $(date +%s) - T0 )) s in)"
}

mkdir -p "$PARTS"
cp -f .whl/warp.part-* "$PARTS"/ 2>/dev/null
cat "$PARTS"/warp.part-* > "/tmp/$WHEEL" 2>/dev/null
if ! echo "$SHA256  /tmp/$WHEEL" | sha256sum -c - ; then
  echo "the warp wheel is incomplete ($(ls "$PARTS" 2>/dev/null | tr '\n' ' ')): the machine went back between the"
  echo "calls; make the stage calls (parts 00, 01) and this one again, back to back"
  exit 3
fi
nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1
nvidia-smi --query-gpu=name,memory.total,clocks.sm,clocks.max.sm,driver_version --format=csv
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "/tmp/$WHEEL" \
  || exit 4
# warpworm itself: the package layout of pyproject.toml (kernels/, render/, dataset_configs/ inside warpworm), copied
# (no build: its pins and extras do not apply there; numpy, h5py, opencv, pyyaml, tqdm are on the image)
rm -rf /tmp/site/warpworm && cp -r warpworm /tmp/site/warpworm && cp -r kernels /tmp/site/warpworm/kernels \
  && cp -r render /tmp/site/warpworm/render && cp -r dataset_configs /tmp/site/warpworm/dataset_configs || exit 4
export PYTHONPATH=/tmp/site
cd /tmp  # so that the repository's own warpworm/ folder (without kernels/) does not shadow the copy
python3 -c "import warp as wp, warpworm, numpy, h5py, cv2, yaml; wp.init(); print('warp', wp.config.version, \
'devices', [d.alias for d in wp.get_devices()], 'numpy', numpy.__version__)" || exit 5

# 1. compile every kernel module for the GPU, in parallel (NVRTC, sm_90 cubin), timed
cat > /tmp/ww_compile.py <<'PY'
import importlib, json, os, pkgutil, sys, time
import warp as wp
wp.config.quiet = True
wp.init()
names = []
for pkg in ("warpworm.kernels", "warpworm.render"):
    for info in pkgutil.iter_modules(importlib.import_module(pkg).__path__):
        n = f"{pkg}.{info.name}"
        importlib.import_module(n)
        if wp.get_module(n).kernels:
            names.append(n)
t0 = time.perf_counter()
wp.force_load(device="cuda:0", modules=[wp.get_module(n) for n in names], max_workers=min(8, os.cpu_count() or 1))
el = time.perf_counter() - t0
print(f"compiled and loaded {names} for cuda:0 in {el:.1f} s")
json.dump({"modules": names, "seconds": el, "device": wp.get_device("cuda:0").name,
           "arch": wp.get_device("cuda:0").arch}, open(os.path.join(os.environ["OUT"], "compile.json"), "w"), indent=1)
PY
export OUT
stage compile 150 python3 /tmp/ww_compile.py

# 2. CUDA against the CPU on identical inputs: the wrench, one substep, a short gait (exactly what the CPU tests check
#    stays true on the GPU path: one thread per world, graph capture)
cat > /tmp/ww_cuda_vs_cpu.py <<'PY'
import json, os, time
import numpy as np
import warp as wp
from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator
quiet_warp()
W, out = 8, {}
p = gaits.preset_params("peristaltic", magnet_model="analytic")
p.hinge_stiffness = np.geomspace(0.004, 0.006, W)  # per-world values: the per-world indexing is exercised too
def build(dev):
    m = Model.from_params(p, W, dev)
    s = Simulator(m, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    return m, s, s.initial_state()
(mc, sc, xc), (mg, sg, xg) = build("cpu"), build("cuda:0")
out["graph_on_cuda"] = bool(sg.use_graph)
def rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-30))
for s_, x_ in ((sc, xc), (sg, xg)):
    s_.update_magnets(x_)
out["wrench_force_rel"] = rel(xc.magnet_force.numpy(), xg.magnet_force.numpy())
out["wrench_torque_rel"] = rel(xc.magnet_torque.numpy(), xg.magnet_torque.numpy())
out["external_force_rel"] = rel(xc.external_force.numpy(), xg.external_force.numpy())
for s_, x_ in ((sc, xc), (sg, xg)):
    s_.run_substeps(x_, 1)
out["one_substep_positions_max_abs_m"] = float(np.abs(xc.positions.numpy() - xg.positions.numpy()).max())
# the block-per-world tile solvers on the GPU against the CPU's band solve, one substep from the same state
from warpworm.sim import simulator as _sim
for solver in [s for s in getattr(_sim, "SOLVERS", ()) if s != "band"]:
    try:
        mt = Model.from_params(p, W, "cuda:0")
        st = Simulator(mt, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, solver=solver)
        xt = st.initial_state()
        st.update_magnets(xt)
        st.run_substeps(xt, 1)
        out[f"one_substep_{solver}_cuda_vs_band_cpu_max_abs_m"] = float(np.abs(xc.positions.numpy()
                                                                              - xt.positions.numpy()).max())
    except Exception as exc:
        out[f"one_substep_{solver}_error"] = f"{type(exc).__name__}: {exc}"[:300]
snaps = {}
for name, s_, x_ in (("cpu", sc, xc), ("cuda", sg, xg)):
    t0 = time.perf_counter()
    s_.settle(x_, 0.05)
    snaps[name] = s_.run(x_, [0.0, 0.25], stack=True)
    wp.synchronize()
    out[f"gait_wall_s_{name}"] = time.perf_counter() - t0
a, b = snaps["cpu"], snaps["cuda"]
out["gait_0p25s_positions_max_abs_m"] = float(np.abs(a["positions"] - b["positions"]).max())
out["gait_0p25s_displacement_mm_cpu"] = (1e3 * (a["positions"][-1] - a["positions"][0]).mean(axis=1)[:, 0]).tolist()
out["gait_0p25s_displacement_mm_cuda"] = (1e3 * (b["positions"][-1] - b["positions"][0]).mean(axis=1)[:, 0]).tolist()
out["unstable_cpu"] = a["unstable"][-1].tolist()
out["unstable_cuda"] = b["unstable"][-1].tolist()
# float32 on both, different instruction order (FMA contraction on the GPU): expect ~1e-6 relative in the wrench and
# ~1e-7 m after one substep; the gait's contacts can amplify that, so the 0.25 s figure is reported, not judged
out["pass"] = bool(out["wrench_force_rel"] < 1e-4 and out["one_substep_positions_max_abs_m"] < 1e-5
                   and out["unstable_cpu"] == out["unstable_cuda"]
                   and all(v < 1e-5 for k, v in out.items() if k.endswith("_cuda_vs_band_cpu_max_abs_m"))
                   and not any(k.endswith("_error") for k in out))
print(json.dumps(out, indent=1))
json.dump(out, open(os.path.join(os.environ["OUT"], "cuda_vs_cpu.json"), "w"), indent=1)
PY
stage cuda_vs_cpu 120 python3 /tmp/ww_cuda_vs_cpu.py

# 3. the summary table on the GPU: every solver at 1k / 16k / 64k worlds, images/s, samples/s ($OUT/summary.json)
stage summary 270 python3 "$REPO/benchmarks/run.py" --device cuda --out "$OUT"

# 4. per-kernel profile on the GPU (no graph: every launch timed after a synchronize)
stage profile 60 python3 "$REPO/benchmarks/profile_step.py" --device cuda --worlds 1024 16384 --duration 0.2 \
  --settle 0.02 --no-levers --out "$OUT/profile_cuda.json"

nvidia-smi --query-gpu=clocks.sm,clocks.max.sm,temperature.gpu,power.draw --format=csv
echo "== done in $(( $(date +%s) - T0 )) s; files: $(ls "$OUT" | tr '\n' ' ')"
sleep 1  # let tee flush the log
