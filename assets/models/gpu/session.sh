#!/usr/bin/env bash
# The next lent GPU's one call (issue 42; README.md here, "The next lent GPU"): first the CUDA build's check
# (cuda_check.sh: tnd sample / pose / eval / train on the GPU against its CPU path, times beside train_torch.py and
# diffusers), then the next training run in the time left (device_run.sh, run b continued from the default: real
# training meshes at 30 % of the pairs, sensor variation, boundary-weighted loss). Everything ends within BUDGET_S
# seconds; the results go to OUT/cuda_check/ and OUT/train/, and OUT/session.log says what ran when.
#
#     [CHECK_S=200] [DEVICE=cuda] bash assets/models/gpu/session.sh OUT [BUDGET_S=450]
#
# Run from the repository root with carry [".dev", ".whl"] (prepared on the development machine, README.md here):
# .dev/tnd-cuda.xz and .dev/cuda-lib/ (build_cuda.sh), .dev/b3.safetensors (the default, f16; train_torch.py reads it
# as f32), .dev/train_meshes.tar.xz (the real training meshes, imported), .whl/ (diffusers and importlib_metadata,
# which the device's PyTorch lacks). The check is cut at CHECK_S so that the training always gets its turn; a failing
# check does not stop the training (PyTorch's path is independent of tnd's CUDA build, which then only generates data
# on the CPU). DEVICE=cpu runs the whole logic on a CPU machine (the dry run; then also BATCH=8 PAIRS=6000).
set -u
out=$1 budget=${2:-450}
t0=$(date +%s)
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../.." && pwd)
mkdir -p "$out"
out=$(cd "$out" && pwd)
log="$out/session.log"
note() { echo "$(( $(date +%s) - t0 )) s: $*" | tee -a "$log"; }
for f in .dev/tnd-cuda.xz .dev/cuda-lib .dev/b3.safetensors .dev/train_meshes.tar.xz; do
    [ -e "$root/$f" ] || { note "missing $f (carry .dev, prepared as README.md here says)"; exit 1; }
done
if ls "$root"/.whl/*.whl > /dev/null 2>&1; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/tnd-site \
        "$root"/.whl/*.whl && export PYTHONPATH="/tmp/tnd-site${PYTHONPATH:+:$PYTHONPATH}"
fi
note "python: $(python3 -c 'import torch, diffusers; print("torch", torch.__version__, "diffusers", diffusers.__version__)' 2>&1 | tail -n 1)"

# The CUDA build, unpacked once: the check's GPU and CPU sides, then the training run's data generator.
mkdir -p /tmp/tnd-session
python3 -c "import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], 'wb'))" \
    "$root/.dev/tnd-cuda.xz" /tmp/tnd-session/tnd && chmod +x /tmp/tnd-session/tnd || { note "cannot unpack tnd"; exit 1; }
export LD_LIBRARY_PATH="$root/.dev/cuda-lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"

# 1. The CUDA build against its CPU path, and beside PyTorch.
timeout "${CHECK_S:-200}" bash "$here/cuda_check.sh" /tmp/tnd-session/tnd /tmp/tnd-session/tnd \
    "$out/cuda_check" "${DEVICE:-cuda}" > "$out/cuda_check.out" 2>&1
note "cuda_check exit $? ($(tail -n 1 "$out/cuda_check.out"))"

# 2. The next training run, with tnd (the CUDA build's CPU path) generating the data on the machine's cores.
left=$(( budget - ($(date +%s) - t0) ))
note "training for ${left} s"
cd "$root" || exit 1
MODELS=b B_INIT=.dev/b3.safetensors LR_B=1e-4 OBJECT_SEED=5 PAIR_SEED=45 PAIRS=${PAIRS:-300000} SAVE_EVERY_S=60 \
    TRAIN_MESHES=.dev/train_meshes.tar.xz MESH_SHARE=0.3 BOUNDARY_WEIGHT=2 INFLATION=0.027,0.033 \
    SENSOR_VARIATION="--camera-offset-range 0.057,0.063 --footprint-scale-range 0.95,1.05 --shadow-range 15,30 --noise-range 0.001,0.0025 --camera-artefacts-range 0,1.5" \
    bash "$here/device_run.sh" /tmp/tnd-session/tnd "$out/train" "$left" > "$out/train.out" 2>&1
note "training exit $?; $(ls "$out/train" | tr '\n' ' ')"
