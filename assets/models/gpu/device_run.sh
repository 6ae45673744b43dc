#!/usr/bin/env bash
# One GPU training session, end to end, on a machine with CUDA PyTorch and 16 cores (see README.md here): the tnd
# release binary (built elsewhere, given as $1) generates the procedural objects and the datasets while two
# trainers (train_torch.py) share the GPU and read the train shards as they appear:
#   a: the shipped default architecture, fine-tuned from assets/models/default.safetensors;
#   b: the wider architecture of wide_config.json here (wide1 with every other setting spelled out), from scratch.
# Everything ends by BUDGET_S seconds after the start; the EMA checkpoints and logs go to OUT.
#
#     [PAIRS=300000] [INFLATION=0.027,0.033] [MODELS="a b"|a|b] [B_INIT=b.safetensors] [LR_B=3e-4] [SAVE_EVERY_S=120] \
#         [OBJECT_SEED=2] [PAIR_SEED=41] [TRAIN_MESHES=.dev/train_meshes.tar.xz] [MESH_SHARE=0.3] \
#         [BOUNDARY_WEIGHT=0] [SENSOR_VARIATION="--camera-offset-range 0.057,0.063 --shadow-range 15,30 ..."] \
#         assets/models/gpu/device_run.sh TND OUT BUDGET_S
set -u
tnd=$1 out=$2 budget=$3
t0=$(date +%s)
here=$(cd "$(dirname "$0")" && pwd)
w=/tmp/tnd-gpu
mkdir -p "$w" "$out"
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader; nproc; df -h /tmp | tail -n 1; } \
    > "$out/gen.log" 2>&1
nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv -l 20 > "$out/smi.log" 2>&1 &
smi=$!
objs="--press 0.001,0.015 --min-contact 0.004"
# Validation objects and pairs: the same commands as data/proc_val in the model card (never trained on).
# --kinds v1: the validation objects of every earlier run (logged validation losses stay comparable).
"$tnd" objects generate "$w/val_objects" --count 300 --seed 1 --builtin-share 0 --kinds v1 >> "$out/gen.log" 2>&1
"$tnd" dataset gen --out "$w/val" --pairs 1000 --seed 12 --objects "$w/val_objects" $objs >> "$out/gen.log" 2>&1
# Training objects: 6 000 procedural objects of every kind (seed 2; plates with holes and swept limbs since
# 2026-11-26, session 9) + the built-in set (a quarter of the draws); inflation drawn
# per pair in 27-33 mm.
# OBJECT_SEED / PAIR_SEED draw fresh training objects and pairs for a continued run (session 15: 3 / 43).
# TRAIN_MESHES: the real-mesh training set (fetch_real_meshes.py --set train, imported with --fit 0.05 --split seen,
# packed with `tar -cJf .dev/train_meshes.tar.xz -C data train_meshes`), mixed in at MESH_SHARE of the pairs.
include=()
if [ -n "${TRAIN_MESHES:-}" ]; then
    tar -xJf "$TRAIN_MESHES" -C "$w" && include=(--include "$w/train_meshes=${MESH_SHARE:-0.3}")
fi
"$tnd" objects generate "$w/objects" --count 6000 --seed "${OBJECT_SEED:-2}" "${include[@]}" >> "$out/gen.log" 2>&1
echo "data ready to stream after $(( $(date +%s) - t0 )) s" >> "$out/gen.log"
# INFLATION= (empty) keeps every pair at the sensor's nominal inflation.
inflation=${INFLATION-0.027,0.033}
# SENSOR_VARIATION: further tnd dataset gen sensor ranges (--camera-offset-range, --footprint-scale-range,
# --shadow-range, --noise-range, --sensor-levels); with them the inflation range is one of the sensor's ranges.
# shellcheck disable=SC2086
nice -n 5 "$tnd" dataset gen --out "$w/train" --pairs "${PAIRS:-300000}" --seed "${PAIR_SEED:-41}" --objects "$w/objects" $objs \
    ${inflation:+--inflation-range "$inflation"} ${SENSOR_VARIATION:-} >> "$out/gen.log" 2>&1 &
gen=$!
left=$(( budget - ($(date +%s) - t0) - 25 ))
save=${SAVE_EVERY_S:-120}
models=${MODELS:-a b}
pa= pb=
if [ "$models" != b ]; then
    python3 "$here/train_torch.py" --data "$w/train" --val-data "$w/val" --init "$here/../default.safetensors" \
        --out "$out/a" --deadline-s "$left" --lr 2e-4 --seed 1 --batch "${BATCH:-256}" --capacity 300000 \
        --save-every-s "$save" --boundary-weight "${BOUNDARY_WEIGHT:-0}" > "$out/a.out" 2>&1 &
    pa=$!
fi
if [ "$models" != a ]; then
    # B_INIT continues an earlier run b (its checkpoint holds the wide config); otherwise b starts from scratch.
    if [ -n "${B_INIT:-}" ]; then start=(--init "$B_INIT"); else start=(--config "$here/wide_config.json"); fi
    python3 "$here/train_torch.py" --data "$w/train" --val-data "$w/val" "${start[@]}" \
        --out "$out/b" --deadline-s "$left" --lr "${LR_B:-3e-4}" --seed 2 --batch "${BATCH:-256}" --capacity 300000 \
        --save-every-s "$save" --boundary-weight "${BOUNDARY_WEIGHT:-0}" > "$out/b.out" 2>&1 &
    pb=$!
fi
wait $pa $pb
kill $gen $smi 2>/dev/null
ls "$w/train/shards" | wc -l >> "$out/gen.log"
echo "done after $(( $(date +%s) - t0 )) s" >> "$out/gen.log"
tail -n 3 "$out"/*.out
