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
