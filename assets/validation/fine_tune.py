"""Your sensor, your model: fine-tune the bundled model on one sensor's own press recordings, on a CPU, and measure it
on other objects pressed by the same sensor.

The sensor is a time-of-flight Soft Bubble (the `tof` condition of depth_camera.py: noise growing with depth², 2 %
random dropouts, a 2-px edge band without returns, flying pixels, a 0.3 mm fixed pattern, the membrane drifting 1 mm
over each recording). As a lab would:

1. press recordings of *training* objects (`--train-objects`, e.g. the disjoint training meshes from
   `fetch_real_meshes.py --set train`; every `--train-stride`-th, default all), one press each, imported one by one with
   `tnd dataset import --from REC` (calibrated from the recording, every contact frame); every 10th recording is kept
   apart as the run's validation data (`--val-data`, the loss it logs only monitors);
2. `tnd train --data <all imported recordings> --init default --steps N` (a budget chosen up front; `--lr`, `--seed`);
3. press recordings of *other* objects (`--eval-objects`, the real-mesh validation set; every `--eval-stride`-th,
   default all; never trained on), imported the same way (every 2nd frame), scored by `tnd eval` defaults with the
   bundled model and with the fine-tuned one: depth (L1 mm, SSIM), pose (pipeline position mm, θ), the threshold
   baseline and the baseline with the same signature check.

Presses, poses and seeds come from --seed (none were tuned on the evaluation objects). Every step is kept on disk and
skipped when its output exists, so a killed run continues where it stopped (training resumes from its checkpoint).
Prints one JSON line per model and a Markdown table.

Usage:
  python3 assets/validation/fine_tune.py --tnd target/release/tnd --train-objects data/train_meshes \\
      --eval-objects data/real_meshes --out data/finetune --steps 1500 [--lr 3e-5] [--seed 700]
Needs only Python's standard library.
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys

import compare_records
from pooled import Pooled, eval_once

TOF = {"noise_exponent": 2.0, "dropout": 0.02, "edge_missing_px": 2.0, "flying_jump_m": 0.005,
       "fixed_pattern_m": 3e-4}
DRIFT_M = -0.001


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}\n{r.stderr[-2000:]}")
    return r


def names_of(objects, stride, offset=0):
    with open(os.path.join(objects, "objects.json")) as f:
        return sorted(o["name"] for o in json.load(f)["objects"])[offset::stride]


def recordings(a, objects, names, folder, split, seed, every):
    """Simulate and import one press recording per object; returns the imported dataset folders."""
    out = []
    rng = random.Random(f"{seed}")
    for k, name in enumerate(names):
        x, y = rng.uniform(-0.004, 0.004), rng.uniform(-0.004, 0.004)
        theta, press = rng.uniform(0, 2 * math.pi), rng.uniform(0.004, 0.008)
        rec = os.path.join(folder, f"{name}.mcap")
        os.makedirs(folder, exist_ok=True)
        if not os.path.exists(rec):
            run([a.tnd, "recording", "simulate", rec, "--objects", objects, "--object", name,
                 f"--pose={x:.5f},{y:.5f},{theta:.5f}", "--max-press", f"{press:.5f}", "--rest", "4",
                 "--ramp", "4", "--seed", str(seed + k), "--sensor", a.sensor, f"--drift={DRIFT_M}"])
        ds = os.path.join(folder, f"{name}.data")
        if not os.path.exists(os.path.join(ds, "manifest.json")):
            r = subprocess.run([a.tnd, "dataset", "import", "-q", "--from", rec, "--objects", objects,
                                "--object", name, "--out", ds, "--split", split, "--every", str(every)],
                               capture_output=True, text=True)
            if r.returncode != 0:
                print(f"{name}: import failed: {r.stderr.strip()[-300:]}", file=sys.stderr)
                continue
        out.append(ds)
    return out


def evaluate(a, datasets, model, tag):
    """`tnd eval` defaults on every dataset; pooled means of depth and pose metrics per method."""
    totals = {}
    for ds in datasets:
        e = eval_once(a.tnd, ds, tag, ["--model", model] if model else [])
        for method in ("model", "model_combined", "baseline", "baseline_checked"):
            for metric in ("position_mm", "theta_rad", "l1_mm", "ssim"):
                totals.setdefault((method, metric), Pooled()).add((e.get(method) or {}).get(metric))
    row = {"model": model or "default"}
    for (method, metric), p in sorted(totals.items()):
        if p.n:
            row[f"{method}.{metric}"] = p.mean()
            row[f"{method}.{metric}.se"] = p.se()
            row[f"{method}.{metric}.n"] = p.n
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tnd", default="tnd")
    ap.add_argument("--train-objects", required=True, help="object set of the sensor's own recordings")
    ap.add_argument("--eval-objects", required=True, help="object set of the other objects it is scored on")
    ap.add_argument("--out", required=True)
    ap.add_argument("--train-stride", type=int, default=1)
    ap.add_argument("--eval-stride", type=int, default=1)
    ap.add_argument("--steps", type=int, required=True, help="training steps (the budget)")
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=3e-5)
    ap.add_argument("--seed", type=int, default=700)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    a.sensor = os.path.join(a.out, "sensor.json")
    with open(a.sensor, "w") as f:
        json.dump({"depth_camera": TOF}, f)

    train_names = names_of(a.train_objects, a.train_stride)
    val_names = train_names[::10]
    fit_names = [n for n in train_names if n not in val_names]
    train_sets = recordings(a, a.train_objects, fit_names, os.path.join(a.out, "train"), "train", a.seed, 1)
    val_sets = recordings(a, a.train_objects, val_names, os.path.join(a.out, "val"), "unseen_objects",
                          a.seed + 5000, 1)
    eval_sets = recordings(a, a.eval_objects, names_of(a.eval_objects, a.eval_stride),
                           os.path.join(a.out, "eval"), "unseen_objects", a.seed + 10000, 2)
    print(json.dumps({"train_recordings": len(train_sets), "val_recordings": len(val_sets),
                      "eval_recordings": len(eval_sets)}), flush=True)

    run_dir = os.path.join(a.out, "run")
    model = os.path.join(run_dir, "model.safetensors")
    log = os.path.join(run_dir, "log.jsonl")
    done = 0
    if os.path.exists(log):
        with open(log) as f:
            steps = [json.loads(l).get("step", 0) for l in f if l.strip()]
            done = max(steps, default=0)
    if done < a.steps or not os.path.exists(model):
        cmd = [a.tnd, "train", "-q", "--data", *train_sets, "--out", run_dir, "--init", "default",
               "--steps", str(a.steps), "--batch", str(a.batch), "--lr", str(a.lr), "--seed", "0"]
        if val_sets:
            cmd += ["--val-data", val_sets[0]]
        print(" ".join(cmd), file=sys.stderr, flush=True)
        run(cmd)

    rows = [evaluate(a, eval_sets, None, "default"), evaluate(a, eval_sets, model, "finetuned")]
    # Paired differences (fine-tuned − default) over the same pairs, as compare_records.py computes them.
    records = {tag: {} for tag in ("default", "finetuned")}
    for ds in eval_sets:
        for tag, merged in records.items():
            for key, rec in compare_records.load(f"{ds}.{tag}.records.jsonl").items():
                merged[(ds, *key)] = rec
    print("\n| metric | pairs | default | fine-tuned | paired difference ± standard error |")
    print("|---|---|---|---|---|")
    for label, keys in compare_records.METRICS:
        d = compare_records.paired(records["default"], records["finetuned"], keys)
        if d:
            print(json.dumps({"metric": label, **d}), file=sys.stderr)
            print(f"| {label} | {d['n']} | {d['a']:.3f} | {d['b']:.3f} | {d['diff']:+.3f} ± {d['se']:.3f} |")
    for r in rows:
        print(json.dumps(r), flush=True)
    f = lambda v: "-" if v is None else f"{v:.3f}"
    # The pipeline is what `tnd pose` reports (eval's model_combined: the first sample's poses with the imprint's
    # proposals, checked); "sample only" is the first sample's estimate alone (eval's model).
    print("\n| model | pairs | depth L1 [mm] | SSIM | pipeline position [mm] | θ [°] | sample only [mm] | "
          "baseline [mm] | baseline + check [mm] | pipeline / baseline | pipeline / baseline + check |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        p, b, bc = (r.get("model_combined.position_mm"), r.get("baseline.position_mm"),
                    r.get("baseline_checked.position_mm"))
        th = r.get("model_combined.theta_rad")
        print(f"| {r['model']} | {r.get('model_combined.position_mm.n')} | {f(r.get('model.l1_mm'))} | "
              f"{f(r.get('model.ssim'))} | {f(p)} ± {f(r.get('model_combined.position_mm.se'))} | "
              f"{f(math.degrees(th) if th is not None else None)} | {f(r.get('model.position_mm'))} | {f(b)} | "
              f"{f(bc)} | {f(p / b if p and b else None)}x | {f(p / bc if p and bc else None)}x |")


if __name__ == "__main__":
    main()
