"""Off-nominal sensors through the recording path, as a user with their own sensor would meet them.

For every validation mesh (an imported object set, e.g. `tnd objects import data/real_meshes --fit 0.05 --split
unseen`), a press recording is simulated by a sensor that is NOT the nominal one (`tnd recording simulate` with the
condition's flags: inflation, footprint, shadow, noise, camera offset, or a non-ellipsoidal membrane mesh), then
imported with `tnd dataset import --from REC` in three ways and scored with `tnd eval` defaults:

  true        the sensor's true settings, --no-calibrate   (what a perfectly informed user gets)
  nominal     nominal settings, --no-calibrate             (the failure: the parametric model trusted as it is)
  calibrated  nominal settings, calibrated from the recording's no-contact frames (the default)

Poses, presses and noise seeds come from --seed (never tuned on). Prints one JSON line per condition and import
mode, and a Markdown table: mean position error of the pipeline, of the threshold baseline and of the baseline with
the same signature check (mm, pooled over every pair), and pipeline / baseline.

Usage:
  python3 assets/validation/offnominal.py --tnd target/release/tnd --objects data/real_meshes --out data/offnominal \
      [--conditions main,inflation+3,...] [--stride 1] [--offset 0] [--seed 300]
Needs only Python's standard library.
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys

from pooled import Pooled, eval_once

# name -> flags of the true sensor (the import's "true" mode passes them; the others do not).
CONDITIONS = {
    "main": ["--inflation", "0.032", "--shadow-px", "28", "--noise-std", "0.0018"],
    "inflation+3": ["--inflation", "0.033"],
    "inflation-3": ["--inflation", "0.027"],
    "footprint+5": ["--footprint", "0.125x0.085"],
    "footprint-5": ["--footprint", "0.115x0.075"],
    "shadow15": ["--shadow-px", "15"],
    "shadow30": ["--shadow-px", "30"],
    "noise1.0": ["--noise-std", "0.001"],
    "noise2.5": ["--noise-std", "0.0025"],
    "camera+3": ["--camera-offset", "0.063"],
    "camera-3": ["--camera-offset", "0.057"],
    "sagging-mesh": None,  # a non-ellipsoidal membrane mesh, written by sagging_membrane()
}


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}\n{r.stderr[-2000:]}")
    return r


def sagging_membrane(path):
    """A Soft Bubble membrane that is no half-ellipsoid: the nominal dome (120 x 80 mm, 30 mm), its top flattened by
    up to 15 % (as an under-inflated membrane sags), as an OBJ in the sensor frame (metres)."""
    rings, segments, a, b, h = 32, 96, 0.06, 0.04, 0.030
    verts = [(0.0, 0.0, h * 0.85)]
    for i in range(1, rings + 1):
        phi = math.pi / 2 * i / rings
        s, c = math.sin(phi), math.cos(phi)
        z = 0.0 if i == rings else h * c * (0.85 + 0.15 * s * s)
        for j in range(segments):
            psi = 2 * math.pi * j / segments
            verts.append((a * s * math.cos(psi), b * s * math.sin(psi), z))
    ring = lambda i, j: 1 + (i - 1) * segments + j % segments
    faces = [(0, ring(1, j), ring(1, j + 1)) for j in range(segments)]
    for i in range(1, rings):
        for j in range(segments):
            faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)), (ring(i, j), ring(i + 1, j + 1), ring(i, j + 1))]
    centre = len(verts)
    verts.append((0.0, 0.0, 0.0))
    faces += [(centre, ring(rings, j + 1), ring(rings, j)) for j in range(segments)]
    with open(path, "w") as f:
        f.writelines(f"v {x:.7f} {y:.7f} {z:.7f}\n" for x, y, z in verts)
        f.writelines(f"f {p + 1} {q + 1} {r + 1}\n" for p, q, r in faces)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tnd", default="tnd")
    ap.add_argument("--objects", required=True, help="object set directory (objects.json)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--conditions", default="main")
    ap.add_argument("--modes", default="true,nominal,calibrated")
    ap.add_argument("--stride", type=int, default=1, help="every n-th object of the set")
    ap.add_argument("--offset", type=int, default=0, help="starting from this one (0-based, sorted by name)")
    ap.add_argument("--every", type=int, default=2, help="import every n-th frame of a recording")
    ap.add_argument("--seed", type=int, default=300)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.objects, "objects.json")) as f:
        names = sorted(o["name"] for o in json.load(f)["objects"])[a.offset :: a.stride]
    rows = []
    for cond in a.conditions.split(","):
        true_flags = CONDITIONS[cond]
        if true_flags is None:
            mesh = os.path.join(a.out, "sagging_membrane.obj")
            sagging_membrane(mesh)
            true_flags = ["--elastomer-mesh", mesh]
        rng = random.Random(f"{a.seed}-{cond}")
        totals = {m: {} for m in a.modes.split(",")}
        for k, name in enumerate(names):
            x, y = rng.uniform(-0.004, 0.004), rng.uniform(-0.004, 0.004)
            theta, press = rng.uniform(0, 2 * math.pi), rng.uniform(0.004, 0.008)
            rec = os.path.join(a.out, cond, f"{name}.mcap")
            os.makedirs(os.path.dirname(rec), exist_ok=True)
            if not os.path.exists(rec):
                run([a.tnd, "recording", "simulate", rec, "--objects", a.objects, "--object", name,
                     f"--pose={x:.5f},{y:.5f},{theta:.5f}", "--max-press", f"{press:.5f}", "--rest", "4",
                     "--ramp", "4", "--seed", str(a.seed + k)] + true_flags)
            for mode in totals:
                ds = os.path.join(a.out, cond, f"{name}.{mode}")
                flags = {"true": true_flags + ["--no-calibrate"], "nominal": ["--no-calibrate"], "calibrated": []}
                if not os.path.exists(os.path.join(ds, "manifest.json")):
                    r = subprocess.run([a.tnd, "dataset", "import", "--from", rec, "--objects", a.objects,
                                        "--object", name, "--out", ds, "--split", "unseen_objects", "--every",
                                        str(a.every)] + flags[mode], capture_output=True, text=True)
                    if r.returncode != 0:
                        print(f"{cond} {name} {mode}: import failed: {r.stderr.strip()[-300:]}", file=sys.stderr)
                        continue
                # The records (each pair's estimate and posterior) feed `tnd posterior` (docs/uncertainty.md).
                e = eval_once(a.tnd, ds)
                for method in ("model", "model_combined", "baseline", "baseline_checked"):
                    totals[mode].setdefault(method, Pooled()).add((e.get(method) or {}).get("position_mm"))
        for mode, t in totals.items():
            mean = {m: p.mean() for m, p in t.items() if p.n}
            row = {"condition": cond, "mode": mode, "pairs": t["model"].n if "model" in t else 0,
                   # The pipeline is what `tnd pose` reports (eval's model_combined); "sample" the first sample's
                   # estimate alone (eval's model), which this script reported as the pipeline before 2026-11-29.
                   "pipeline_mm": mean.get("model_combined") or mean.get("model"), "sample_mm": mean.get("model"),
                   "baseline_mm": mean.get("baseline"),
                   "baseline_checked_mm": mean.get("baseline_checked")}
            row["pipeline_over_baseline"] = row["pipeline_mm"] / row["baseline_mm"] if row["baseline_mm"] else None
            print(json.dumps(row), flush=True)
            rows.append(row)
    print("\n| condition | import | pairs | pipeline [mm] | sample only | threshold baseline | baseline + check | "
          "pipeline / baseline |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        f = lambda v: "-" if v is None or v != v else f"{v:.2f}"
        print(f"| {r['condition']} | {r['mode']} | {r['pairs']} | {f(r['pipeline_mm'])} | {f(r['sample_mm'])} | "
              f"{f(r['baseline_mm'])} | "
              f"{f(r['baseline_checked_mm'])} | {f(r['pipeline_over_baseline'])}x |")


if __name__ == "__main__":
    main()
