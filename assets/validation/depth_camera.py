"""Real depth-camera frames through the recording path, artefact by artefact, as a user with their own sensor meets them.

For every validation mesh (an imported object set, e.g. `tnd objects import data/real_meshes --fit 0.05 --split
unseen`) one press recording per condition is simulated with the same pose, press and noise seed, the depth camera's
artefacts switched on one at a time (a sensor file's `depth_camera` section; `tnd recording simulate --drift` for the
membrane's drift), then imported as a user would — `tnd dataset import --from REC` with the object's true pose,
calibrated from the recording (the default) — and scored with `tnd eval` defaults. Conditions whose name ends in
`-nan` are written as 32FC1 (NaN where no return) and go through the *frame-folder* path: `tnd recording frames`
writes the native .npy frames (NaN where no return), and that folder is imported with `--poses poses.csv`. The others are 16UC1 MCAP
files (0 where no return).

Poses, presses and seeds come from --seed (never tuned on). Prints one JSON line per condition and a Markdown table:
pairs, mean position error of the pipeline, of the threshold baseline and of the baseline with the same signature
check (mm, pooled over every pair; ± one standard error of the pipeline's mean), pipeline / baseline, pipeline /
its error on the clean recordings, and — with `clean` first among the conditions — the same on the frames both
conditions imported (pairs keyed by object and recording frame): the means' ratio, the medians, and the typical
pair's ratio (geometric mean). Each evaluation's per-pair records are kept beside it (`*.records.jsonl`).

Usage:
  python3 assets/validation/depth_camera.py --tnd target/release/tnd --objects data/real_meshes --out data/depthcam \
      [--conditions clean,missing,...] [--stride 2] [--seed 500]
Needs only Python's standard library.
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys

from pooled import Pooled, eval_once, records_by_frame, same_frames

TOF = {"noise_exponent": 2.0, "dropout": 0.02, "edge_missing_px": 2.0, "flying_jump_m": 0.005,
       "fixed_pattern_m": 3e-4}

# name -> (depth_camera settings, drift of the inflation over the recording in metres)
CONDITIONS = {
    "clean": ({}, 0.0),
    "missing": ({"dropout": 0.05, "edge_missing_px": 4.0}, 0.0),
    "missing-nan": ({"dropout": 0.05, "edge_missing_px": 4.0}, 0.0),
    "depth-noise": ({"noise_exponent": 2.0}, 0.0),
    "fixed-pattern": ({"fixed_pattern_m": 5e-4}, 0.0),
    "flying": ({"flying_jump_m": 0.005}, 0.0),
    "drift": ({}, -0.001),
    "tof": (TOF, -0.001),
    "tof-nodrift": (TOF, 0.0),
    "tof-nan": (TOF, -0.001),
}


def run(cmd, **kw):
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}\n{r.stderr[-2000:]}")
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tnd", default="tnd")
    ap.add_argument("--objects", required=True, help="object set directory (objects.json)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument("--stride", type=int, default=2, help="every n-th object of the set")
    ap.add_argument("--every", type=int, default=1,
                    help="import every n-th frame of a recording (2 halves the time but skips the peak frame of a "
                         "short press, frame 7 of 15: fewer recordings import)")
    ap.add_argument("--seed", type=int, default=500)
    ap.add_argument("--import-flags", default="", help="extra flags for tnd dataset import (space-separated)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.objects, "objects.json")) as f:
        names = sorted(o["name"] for o in json.load(f)["objects"])[:: a.stride]
    rows = []
    for cond in a.conditions.split(","):
        camera, drift = CONDITIONS[cond]
        nan = cond.endswith("-nan")
        sensor = os.path.join(a.out, f"{cond}.sensor.json")
        with open(sensor, "w") as f:
            json.dump({"depth_camera": camera}, f)
        rng = random.Random(f"{a.seed}")  # the same presses in every condition
        totals = {}
        failures = []
        imported = []
        for k, name in enumerate(names):
            x, y = rng.uniform(-0.004, 0.004), rng.uniform(-0.004, 0.004)
            theta, press = rng.uniform(0, 2 * math.pi), rng.uniform(0.004, 0.008)
            rec = os.path.join(a.out, cond, f"{name}.mcap")
            os.makedirs(os.path.dirname(rec), exist_ok=True)
            if not os.path.exists(rec):
                run([a.tnd, "recording", "simulate", rec, "--objects", a.objects, "--object", name,
                     f"--pose={x:.5f},{y:.5f},{theta:.5f}", "--max-press", f"{press:.5f}", "--rest", "4",
                     "--ramp", "4", "--seed", str(a.seed + k), "--sensor", sensor, f"--drift={drift}",
                     "--encoding", "f32" if nan else "mm16"])
            source, pose_flags = rec, []
            if nan:
                folder = os.path.join(a.out, cond, f"{name}.frames")
                if not os.path.exists(os.path.join(folder, "frames.csv")):
                    run([a.tnd, "recording", "frames", rec, "--out", folder])
                poses = os.path.join(a.out, cond, f"{name}.poses.csv")
                with open(os.path.join(folder, "frames.csv")) as f:
                    frames = [line.split(",")[0] for line in f.read().splitlines()[1:]]
                with open(poses, "w") as f:
                    f.write("frame,x,y,theta\n")
                    for fr in frames:
                        f.write(f"{fr},{x:.5f},{y:.5f},{theta:.5f}\n")
                source, pose_flags = folder, ["--poses", poses]
            ds = os.path.join(a.out, cond, f"{name}.data")
            if not os.path.exists(os.path.join(ds, "manifest.json")):
                r = subprocess.run([a.tnd, "dataset", "import", "--from", source, "--objects", a.objects,
                                    "--object", name, "--out", ds, "--split", "unseen_objects", "--every",
                                    str(a.every)] + pose_flags + a.import_flags.split(),
                                   capture_output=True, text=True)
                if r.returncode != 0:
                    failures.append(name)
                    print(f"{cond} {name}: import failed: {r.stderr.strip()[-300:]}", file=sys.stderr)
                    continue
            e = eval_once(a.tnd, ds)
            imported.append(ds)
            for method in ("model", "model_combined", "baseline", "baseline_checked"):
                totals.setdefault(method, Pooled()).add((e.get(method) or {}).get("position_mm"))
        mean = {m: t.mean() if t.n else None for m, t in totals.items()}
        se = {m: t.se() if t.n else None for m, t in totals.items()}
        row = {"condition": cond, "recordings": len(names), "imported": len(names) - len(failures),
               # The pipeline is what `tnd pose` reports (eval's model_combined: the first sample's poses and the
               # imprint's proposals, checked); "sample" the first sample's estimate alone (eval's model). Before
               # 2026-11-29 this script reported the latter as the pipeline.
               "pairs": totals["model"].n if "model" in totals else 0,
               "pipeline_mm": mean.get("model_combined") or mean.get("model"),
               "pipeline_se_mm": se.get("model_combined") or se.get("model"), "sample_mm": mean.get("model"),
               "baseline_mm": mean.get("baseline"), "baseline_checked_mm": mean.get("baseline_checked")}
        row["pipeline_over_baseline"] = row["pipeline_mm"] / row["baseline_mm"] if row["baseline_mm"] else None
        # The same frames in the clean condition (run first): what the artefacts cost on identical presses.
        row["_records"] = records_by_frame(imported)
        clean_records = next((r["_records"] for r in rows if r["condition"] == "clean"), None)
        row["same_frames"] = same_frames(clean_records, row["_records"]) if clean_records else None
        print(json.dumps({k: v for k, v in row.items() if not k.startswith("_")}), flush=True)
        rows.append(row)
    clean = next((r["pipeline_mm"] for r in rows if r["condition"] == "clean"), None)
    print("\n| condition | imported | pairs | pipeline [mm] | sample only | threshold baseline | baseline + check | "
          "pipeline / baseline | pipeline / clean | same frames: pairs, pipeline / clean, median vs clean, typical pair |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    def same(s):
        if not s:
            return "-"
        return (f"{s['pairs']}, {s['mm']:.2f} / {s['clean_mm']:.2f} ({s['ratio']:.2f}x), {s['median_mm']:.2f} vs "
                f"{s['clean_median_mm']:.2f}, {s['typical_ratio']:.2f}x")

    for r in rows:
        f = lambda v: "-" if v is None or v != v else f"{v:.2f}"
        vs_clean = r["pipeline_mm"] / clean if clean and r["pipeline_mm"] else None
        print(f"| {r['condition']} | {r['imported']} of {r['recordings']} | {r['pairs']} | "
              f"{f(r['pipeline_mm'])} ± {f(r['pipeline_se_mm'])} | {f(r['sample_mm'])} | "
              f"{f(r['baseline_mm'])} | {f(r['baseline_checked_mm'])} | {f(r['pipeline_over_baseline'])}x | "
              f"{f(vs_clean)}x | {same(r['same_frames'])} |")


if __name__ == "__main__":
    main()
