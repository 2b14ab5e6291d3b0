#!/usr/bin/env bash
# The one GPU check of warpworm (issue #28): CUDA against the CPU on the same inputs (physics, then whole datasets),
# then speed (worm-substeps/s and GPU memory at 1k, 16k, 64k worlds; images/s; samples/s) and a per-kernel profile,
# all written to $OUT.
#
# warp-lang is not on the GPU machine and nothing can be downloaded there. Its wheel (149 MB) unpacked without its
# examples and tests, as one tar.xz (98 MB), travels in two parts (a call carries at most 64 MiB). The machine keeps
# files only while warm (30 s after a call), so make the two calls BACK TO BACK, nothing in between:
#
#   here, once:   bash benchmarks/gpu_check.sh prepare    # .whl/warp.part-00, -01, warp-site.sha256 (~3 min of xz)
#   device run 1: command "bash benchmarks/gpu_check.sh stage", carry [".whl/warp.part-00"], timeout_s 120
#   device run 2: command "bash benchmarks/gpu_check.sh run", carry [".whl/warp.part-01", ".whl/warp-site.sha256",
#                 ".whl/py"], timeout_s 580
#
# 'run' refuses (exit 3, in seconds) when the part of the first call is gone (the machine went back between calls):
# start again from run 1. 'run' keeps itself within BUDGET_S (default 520 s) by giving each stage what is left, so
# the call ends inside 9 minutes; each stage's failure is logged and the next stage still runs.
# Back (at most 8 files): gpu_check.log (everything printed, nvidia-smi's report first), compile.json,
# cuda_vs_cpu.json, datasets_cuda_vs_cpu.json, dynamics_cuda.json, render.json, headlines_cuda.json,
# profile_cuda.json.
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
  rm -rf .whl/site .whl/warp.part-* .whl/warp-site.tar.xz .whl/py
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl/py \
    pydantic==2.13.4 pydantic-core==2.46.4 annotated-types==0.7.0 typing-inspection==0.4.2 typing-extensions==4.15.0 \
    || exit 1
  mkdir -p .whl/site && (cd .whl/site && unzip -q "../$WHEEL" && rm -rf warp/examples warp/tests) || exit 1
  tar -cf - -C .whl/site . | xz -T0 -9e > .whl/warp-site.tar.xz || exit 1
  rm -rf .whl/site
  (cd .whl && sha256sum warp-site.tar.xz > warp-site.sha256)
  split -b 50M -d -a 2 .whl/warp-site.tar.xz .whl/warp.part-
  ls -la .whl
  [ "$(ls .whl/warp.part-* | wc -l)" = 2 ] || echo "WARNING: not two parts: add a stage call per extra part"
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
BUDGET_S=${BUDGET_S:-520}
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
cat "$PARTS"/warp.part-* > /tmp/warp-site.tar.xz 2>/dev/null
if ! (cd /tmp && sha256sum -c "$REPO/.whl/warp-site.sha256"); then  # the file names warp-site.tar.xz
  echo "warp is incomplete ($(ls "$PARTS" 2>/dev/null | tr '\n' ' ')): the machine went back between the calls;"
  echo "make the stage call (part 00) and this one again, back to back"
  exit 3
fi
nvidia-smi
nvidia-smi --query-gpu=name,memory.total,clocks.sm,clocks.max.sm,driver_version --format=csv
rm -rf /tmp/site && mkdir -p /tmp/site
# pydantic (the config schema) is not on the image either: its wheels (2.6 MB) travel in .whl/py
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .whl/py/*.whl || exit 4
tar -xJf /tmp/warp-site.tar.xz -C /tmp/site || exit 4
# warpworm itself: the package layout of pyproject.toml (kernels/, render/, dataset_configs/ inside warpworm), copied
# (no build: its pins and extras do not apply there; numpy, h5py, opencv, pyyaml, tqdm are on the image)
cp -r warpworm /tmp/site/warpworm && cp -r kernels /tmp/site/warpworm/kernels \
  && cp -r render /tmp/site/warpworm/render && cp -r dataset_configs /tmp/site/warpworm/dataset_configs || exit 4
export PYTHONPATH=/tmp/site
cd /tmp  # so that the repository's own warpworm/ folder (without kernels/) does not shadow the copy
python3 -c "import warp as wp, warpworm, numpy, h5py, cv2, yaml; wp.init(); print('warp', wp.config.version, \
'devices', [d.alias for d in wp.get_devices()], 'numpy', numpy.__version__)" || exit 5
python3 -m pip list 2>/dev/null | grep -iE "^(numpy|h5py|opencv|pyyaml|pydantic|tqdm|trimesh|usd|scipy) " 

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

# 3. whole datasets on CUDA against the CPU, same seed: the default config and production's looks at 128² (the
#    pipeline promises the same draws -- params, cameras, seeds -- on any device; the physics and pixels are float32
#    on both, in another instruction order, so they are reported, not judged)
cat > /tmp/ww_datasets.py <<'PY'
import json, os, sys, time
sys.path.insert(0, os.path.join(os.environ["REPO"], "benchmarks"))
from compare_datasets import compare_folders
from pathlib import Path
from warpworm.data.config import load_config
from warpworm.data.job import generate
out, root = {}, Path("/tmp/ww_ds")
for name, extra in (("default", []), ("production", ["render.width=128", "render.height=128"])):
    for dev in ("cuda:0", "cpu"):
        cfg = load_config(name, extra + [f"sim.device={dev}", "output.preview=false"], num_samples=32)
        t0 = time.perf_counter()
        generate(cfg, root / name / dev.replace(":", ""), progress=False)
        out[f"{name}_wall_s_{dev}"] = time.perf_counter() - t0
    res = compare_folders(root / name / "cuda0", root / name / "cpu")
    out[name] = {"identical": res["identical"], "problems": res["problems"],
                 "n_identical": sum(r["identical"] for r in res["rows"]), "n_datasets": len(res["rows"]),
                 "differing": {r["dataset"]: {k: v for k, v in r.items() if k != "dataset"}
                               for r in res["rows"] if not r["identical"]}}
    print(name, json.dumps(out[name], indent=1, default=str)[:4000])
json.dump(out, open(os.path.join(os.environ["OUT"], "datasets_cuda_vs_cpu.json"), "w"), indent=1, default=str)
PY
export REPO
stage datasets 120 python3 /tmp/ww_datasets.py

# 4. dynamics on the GPU: every solver at 1k / 16k / 64k worlds with the GPU memory each holds, written after each
#    size ($OUT/dynamics_cuda.json), so that a stage stopped by its limit keeps the sizes it finished
cat > /tmp/ww_dynamics.py <<'PY'
import json, os, sys
sys.path.insert(0, os.path.join(os.environ["REPO"], "benchmarks"))
import bench_dynamics
rows = []
for W in (1024, 16384, 65536):
    rows += [r for r in bench_dynamics.compare("cuda:0", sizes=(W,), numpy_reference=W == 1024) if r.get("W") == W]
    json.dump(rows, open(os.path.join(os.environ["OUT"], "dynamics_cuda.json"), "w"), indent=1, default=float)
    for r in rows[-8:]:
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items() if k != "note"})
PY
stage dynamics 200 python3 /tmp/ww_dynamics.py

# 5. the renderer on the GPU: images/s at 128², 256², 512² (1,024 images a batch) against the ray caster, and each
#    realism option on and off ($OUT/render.json)
stage render 80 python3 "$REPO/benchmarks/run.py" render --device cuda --out "$OUT"

# 6. samples/s of the pipeline end to end on CUDA: the summary's headline rows ($OUT/headlines_cuda.json)
cat > /tmp/ww_headlines.py <<'PY'
import json, os, sys
sys.path.insert(0, os.path.join(os.environ["REPO"], "benchmarks"))
rows = []
for name in ("dataset", "views"):
    try:
        rows.append(__import__(f"bench_{name}").headline("cuda:0"))
    except Exception as exc:
        rows.append({"system": name, "note": f"failed: {type(exc).__name__}: {exc}"[:300]})
    print(rows[-1])
    json.dump(rows, open(os.path.join(os.environ["OUT"], "headlines_cuda.json"), "w"), indent=1, default=float)
PY
stage headlines 70 python3 /tmp/ww_headlines.py

# 7. per-kernel profile on the GPU (no graph: every launch timed after a synchronize)
stage profile 45 python3 "$REPO/benchmarks/profile_step.py" --device cuda --worlds 1024 16384 --duration 0.2 \
  --settle 0.02 --no-levers --out "$OUT/profile_cuda.json"

nvidia-smi --query-gpu=clocks.sm,clocks.max.sm,temperature.gpu,power.draw --format=csv
echo "== done in $(( $(date +%s) - T0 )) s; files: $(ls "$OUT" | tr '\n' ' ')"
sleep 1  # let tee flush the log
