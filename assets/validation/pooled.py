"""What the validation scripts share: `tnd eval` run once per dataset (its summary kept beside it), and metrics
pooled over datasets from each one's count, mean and standard deviation. Standard library only."""

import json
import math
import os
import subprocess


def eval_once(tnd, ds, tag="", extra=()):
    """`tnd eval` of dataset `ds`'s unseen_objects split with its per-pair records kept beside it (`ds[.tag].records.
    jsonl`); the summary line is written to `ds[.tag].eval.json` and read from there when it exists."""
    stem = f"{ds}.{tag}" if tag else ds
    out = stem + ".eval.json"
    if not os.path.exists(out):
        cmd = [tnd, "eval", "--data", ds, "--split", "unseen_objects", "--json", "--records",
               stem + ".records.jsonl", *extra]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}\n{r.stderr[-2000:]}")
        with open(out, "w") as f:
            f.write(r.stdout.strip().splitlines()[-1] + "\n")
    with open(out) as f:
        return json.load(f)


class Pooled:
    """A mean and its standard error over pairs pooled from several datasets' (n, mean, std) summaries."""

    def __init__(self):
        self.n, self.sum, self.sum_sq = 0, 0.0, 0.0

    def add(self, summary):
        """Add a `tnd eval` MeanStd summary ({"n", "mean", "std"}); summaries without pairs are skipped."""
        n = (summary or {}).get("n") or 0
        if n:
            mean, std = summary["mean"], summary.get("std") or 0.0
            self.n += n
            self.sum += mean * n
            self.sum_sq += (n - 1) * std ** 2 + n * mean ** 2

    def mean(self):
        return self.sum / self.n if self.n else float("nan")

    def se(self):
        if not self.n:
            return float("nan")
        m = self.mean()
        return math.sqrt(max(self.sum_sq / self.n - m * m, 0.0) / max(self.n - 1, 1))


def records_by_frame(datasets):
    """The pairs of imported recordings' `tnd eval` records keyed by (object, recording frame): each dataset
    `NAME.data` beside its `NAME.data.records.jsonl`, its `frames.csv` mapping a pair's index to the frame. Keyed so,
    two conditions' pairs are the same frames even where their contact frames differ (pair indices then do not)."""
    out = {}
    for ds in datasets:
        rec, frames = ds + ".records.jsonl", os.path.join(ds, "frames.csv")
        if not (os.path.exists(rec) and os.path.exists(frames)):
            continue
        with open(frames) as f:
            frame_of = {int(r.split(",")[0]): int(r.split(",")[1]) for r in f.read().splitlines()[1:] if r}
        name = os.path.basename(ds).rsplit(".data", 1)[0]
        with open(rec) as f:
            for line in f:
                row = json.loads(line)
                if "record" in row and row["index"] in frame_of:
                    out[(name, frame_of[row["index"]])] = row["record"]
    return out


def same_frames(base, other):
    """`other` against `base` (records_by_frame) on the frames both hold: pairs, the pipeline's mean and median
    position error in each (mm), the ratio of the means, and the geometric mean of the per-pair ratio of
    (error + 0.05 mm): the typical pair rather than the tails."""
    def err(r):  # the pipeline; records without the signature check have only the sample's estimate
        return ((r.get("model_combined") or r.get("model") or {}).get("pose") or {}).get("position_mm")
    pairs = [(err(base[k]), err(other[k])) for k in base if k in other]
    pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
    if not pairs:
        return None
    a, b = [p[0] for p in pairs], [p[1] for p in pairs]
    mid = lambda v: sorted(v)[len(v) // 2] if len(v) % 2 else sum(sorted(v)[len(v) // 2 - 1:len(v) // 2 + 1]) / 2
    geo = math.exp(sum(math.log((y + 0.05) / (x + 0.05)) for x, y in pairs) / len(pairs))
    return {"pairs": len(pairs), "clean_mm": sum(a) / len(a), "mm": sum(b) / len(b),
            "ratio": sum(b) / sum(a) if sum(a) > 0 else float("nan"),
            "clean_median_mm": mid(a), "median_mm": mid(b), "typical_ratio": geo}
