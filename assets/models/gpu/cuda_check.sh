#!/usr/bin/env bash
# The CUDA build's check on a GPU machine, in one call (README.md here, "A CUDA build of tnd"): `tnd sample`, `tnd pose`,
# `tnd eval` and `tnd train` with `--device cuda` against the CPU build with the same seeds, the training step
# beside train_torch.py (PyTorch) and the sampling step beside diffusers' DDIM loop on the same GPU. Everything goes to OUT: check.log (the verdicts and times, also
# printed), the commands' own logs, and compare.json.
#
#     [SHORT_STEPS=20] [LONG_STEPS=120] [SAMPLE_SHORT=25] [SAMPLE_LONG=225] \
#         assets/models/gpu/cuda_check.sh TND_CPU TND_CUDA OUT [DEVICE]
#
# TND_CUDA is build_cuda.sh's .dev/tnd-cuda.xz (unpacked here; its libcudart beside it in cuda-lib/); the CUDA 13 cuBLAS,
# cuRAND and NVRTC it loads are looked for in the Python packages (PyTorch's nvidia/* wheels). TND_CPU may be the same
# file: the CUDA build's CPU path is the CPU build's (the dry run below gives identical outputs from both), so one
# binary need be carried. DEVICE defaults to cuda; with
# DEVICE=cpu and TND_CUDA=TND_CPU the script runs its whole logic on a CPU machine (the dry run).
#
# Tolerances: the samples start from the same noise (drawn on the CPU from the seed) and run the same deterministic
# DDIM steps, so they differ only by float rounding (GPU reductions, cuBLAS): max |Δ| ≤ 1e-4 m (0.1 mm, a fourteenth
# of the sensor noise σ = 1.38 mm). Poses and eval errors go through argmin choices that a 0.1 mm change can flip on
# an ambiguous object: the pose check asks for ≤ 1 mm between the two estimates, the eval check for mean sample L1
# within 0.1 mm and mean pipeline position errors within 0.5 mm; all print the numbers either way.
set -u
cpu=$1 gpu=$2 out=$3 device=${4:-cuda}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
out=$(cd "$out" && pwd)
w=${TMPDIR:-/tmp}/tnd-cuda-check
rm -rf "$w"
mkdir -p "$w"
log="$out/check.log"
cuda_lib="$(cd "$(dirname "$gpu")" && pwd)/cuda-lib"
# unpack FILE NAME: FILE itself, or FILE.xz unpacked to $w/NAME.
unpack() {
    if [ "${1%.xz}" = "$1" ]; then echo "$1"; return; fi
    "${PYTHON:-python3}" -c "import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], 'wb'))" \
        "$1" "$w/$2" && chmod +x "$w/$2" && echo "$w/$2"
}
gpu=$(unpack "$gpu" tnd-cuda) || { echo "cannot unpack $2" >&2; exit 1; }
if [ "$1" = "$2" ]; then cpu=$gpu; else cpu=$(unpack "$cpu" tnd-cpu) || { echo "cannot unpack $1" >&2; exit 1; }; fi
: > "$log"
say() { echo "$*" | tee -a "$log"; }
py=${PYTHON:-python3}

if [ "$device" != cpu ]; then
    say "gpu: $(nvidia-smi --query-gpu=name,driver_version,compute_cap,memory.total --format=csv,noheader 2>&1)"
    # The CUDA 13 libraries candle loads when it opens the device.
    libs=$("$py" - <<'EOF'
import pathlib, site, sys
roots = [pathlib.Path(p) for p in site.getsitepackages() + [site.getusersitepackages()]]
wanted = ["libcublas.so.13", "libcublasLt.so.13", "libcurand.so.10", "libnvrtc.so.13"]
dirs = []
for name in wanted:
    for root in roots:
        hits = sorted((root / "nvidia").glob(f"**/{name}")) if (root / "nvidia").is_dir() else []
        if hits:
            if str(hits[0].parent) not in dirs:
                dirs.append(str(hits[0].parent))
            break
    else:
        print(f"missing {name}", file=sys.stderr)
print(":".join(dirs))
EOF
)
    export LD_LIBRARY_PATH="${libs}${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
# libcudart, which the CUDA build links, from build_cuda.sh's cuda-lib/ beside the binary.
[ -d "$cuda_lib" ] && export LD_LIBRARY_PATH="$cuda_lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
say "libraries: ${LD_LIBRARY_PATH:-}"

# run NAME CMD...: runs CMD with its output in OUT/NAME.log, records its wall time and exit status.
declare -A secs
run() {
    local name=$1
    shift
    local t0 t1
    t0=$(date +%s.%N)
    "$@" > "$out/$name.log" 2>&1
    local rc=$?
    t1=$(date +%s.%N)
    secs[$name]=$("$py" -c "print(round($t1 - $t0, 2))")
    say "$name: ${secs[$name]} s, exit $rc"
    [ "$rc" -eq 0 ] || { say "$name failed; the end of its log:"; tail -n 5 "$out/$name.log" | tee -a "$log"; }
    return "$rc"
}

# One contact and a small dataset, made by the CPU build.
"$cpu" sim --object cross_w12_s50 --pose 0.002,-0.001,0.35 --press 0.006 --seed 1 --out "$w/sim" > /dev/null
"$cpu" dataset gen --out "$w/ds" --pairs 60 --seed 2 > /dev/null 2>&1
imprint=(--imprint "$w/sim/imprint.npy" --signature "$w/sim/signature.npy")

for b in cpu dev; do
    if [ "$b" = cpu ]; then bin=$cpu d=cpu; else bin=$gpu d=$device; fi
    run "sample_$b" "$bin" sample "${imprint[@]}" --samples 8 --steps 50 --seed 3 --device "$d" --out "$w/sample_$b"
    run "pose_$b" "$bin" pose "${imprint[@]}" --object cross_w12_s50 --truth 0.002,-0.001,0.35 --samples 8 --steps 50 \
        --seed 3 --device "$d" --out "$w/pose_$b"
    run "eval_$b" "$bin" eval --data "$w/ds" --split unseen_objects --limit 8 --steps 50 --seed 3 --json --device "$d" \
        --records "$w/eval_$b.jsonl"
done

# Sampling speed: `tnd sample --no-guidance` (the loop diffusers runs) at two step counts, so that start-up (process,
# model load, CUDA context, kernel compilation) cancels in the difference, and diffusers' DDIM loop on the same model
# (exported by tnd) in process, after a warm-up; both 16 samples at once, f32.
"$cpu" model export --diffusers "$w/diffusers" > /dev/null
s_short=${SAMPLE_SHORT:-25} s_long=${SAMPLE_LONG:-225}
for steps in "$s_short" "$s_long"; do
    run "sample_time_${steps}" "$gpu" sample "${imprint[@]}" --no-guidance --samples 16 --steps "$steps" --seed 3 \
        --device "$device" --out "$w/sample_time_${steps}"
done
run diffusers_sample "$py" "$here/diffusers_sample_time.py" "$w/diffusers" --samples 16 --steps "$s_short" --runs 3 \
    --device "$device"

# Training: the same start, data, batch and seed; the time per step from a short and a long run (start-up cancels).
init="$here/../default.safetensors"
short=${SHORT_STEPS:-20} long=${LONG_STEPS:-120}
for steps in "$short" "$long"; do
    run "train_${steps}_dev" "$gpu" train --data "$w/ds" --val-data "$w/ds" --init "$init" --out "$w/train_${steps}" \
        --steps "$steps" --batch 32 --seed 1 --checkpoint-every-steps 100000 --device "$device"
    run "torch_${steps}" "$py" "$here/train_torch.py" --data "$w/ds" --val-data "$w/ds" --init "$init" \
        --out "$w/torch_${steps}" --deadline-s 500 --max-steps "$steps" --batch 32 --min-pairs 8 --capacity 64 \
        --seed 1 --device "$device"
done

"$py" - "$w" "$out" "${secs[train_${short}_dev]:-nan}" "${secs[train_${long}_dev]:-nan}" "${secs[torch_${short}]:-nan}" \
    "${secs[torch_${long}]:-nan}" "$short" "$long" "${secs[sample_time_${s_short}]:-nan}" \
    "${secs[sample_time_${s_long}]:-nan}" "$s_short" "$s_long" <<'EOF' | tee -a "$log"
import json, math, sys
import numpy as np
w, out = sys.argv[1], sys.argv[2]
t20, t120, p20, p120 = (float(x) for x in sys.argv[3:7])
short, long = int(sys.argv[7]), int(sys.argv[8])
s_t_short, s_t_long = float(sys.argv[9]), float(sys.argv[10])
s_short, s_long = int(sys.argv[11]), int(sys.argv[12])
res, ok = {}, True
def check(name, value, tol, unit):
    global ok
    good = value <= tol
    ok &= good
    res[name] = {"value": value, "tolerance": tol}
    print(f"{name}: {value:.3g} {unit} (tolerance {tol:g}) {'ok' if good else 'FAILED'}")
try:
    a, b = np.load(f"{w}/sample_cpu/samples.npy"), np.load(f"{w}/sample_dev/samples.npy")
    check("sample max |cpu - device|", float(np.abs(a - b).max()), 1e-4, "m")
    p, q = (json.load(open(f"{w}/pose_{s}/pose.json"))["estimate"] for s in ("cpu", "dev"))
    check("pose |cpu - device|", math.hypot(p["x"] - q["x"], p["y"] - q["y"]), 1e-3, "m")
    def records(s):
        lines = (json.loads(l) for l in open(f"{w}/eval_{s}.jsonl"))
        return [l["record"] for l in lines if "record" in l]
    def mean(s, key):
        return float(np.mean([key(r) for r in records(s)]))
    l1 = lambda r: r["model"]["depth"]["l1_mm"]
    pos = lambda r: r["model_combined"]["pose"]["position_mm"]
    check("eval mean sample L1 |cpu - device|", abs(mean("cpu", l1) - mean("dev", l1)), 0.1, "mm")
    check("eval mean pipeline position error |cpu - device|", abs(mean("cpu", pos) - mean("dev", pos)), 0.5, "mm")
except Exception as err:  # a missing output: the step's log says why
    ok = False
    print(f"comparison failed: {err!r}")
tnd_step, torch_step = (t120 - t20) / (long - short), (p120 - p20) / (long - short)
res["train_s_per_step"] = {"tnd": tnd_step, "train_torch.py": torch_step, "ratio": tnd_step / torch_step}
print(f"training step, batch 32: tnd {tnd_step:.4f} s, train_torch.py {torch_step:.4f} s, ratio {tnd_step / torch_step:.2f}")
try:
    peer = json.loads(open(f"{out}/diffusers_sample.log").read().strip().splitlines()[-1])
    tnd_step = (s_t_long - s_t_short) / (s_long - s_short)
    res["sample_s_per_step_16"] = {"tnd": tnd_step, "diffusers": peer["s_per_step"],
                                   "ratio": tnd_step / peer["s_per_step"],
                                   f"tnd_process_s_{s_short}_steps": s_t_short,
                                   f"diffusers_loop_s_{s_short}_steps": peer["loop_s"]}
    print(f"sampling step, 16 samples: tnd {tnd_step:.4f} s, diffusers {peer['s_per_step']:.4f} s, ratio "
          f"{tnd_step / peer['s_per_step']:.2f}; {s_short} steps: tnd process {s_t_short:.2f} s (start-up included), "
          f"diffusers loop {peer['loop_s']:.2f} s")
except Exception as err:  # the timing runs' logs say why
    ok = False
    print(f"sampling timing failed: {err!r}")
json.dump(res, open(f"{out}/compare.json", "w"), indent=1)
print("cuda_check:", "all checks passed" if ok else "FAILED")
sys.exit(0 if ok else 1)
EOF
