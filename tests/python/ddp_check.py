#!/usr/bin/env python3
"""Data-parallel train_torch.py is the single-process run: checks two checkpoints of the same command and seed.

    ddp_check.py INIT ONE TWO

INIT is the checkpoint both started from, ONE the output of `python3 train_torch.py ...` and TWO of
`torchrun --nproc_per_node N train_torch.py ...` with the same arguments. Every rank trains on its slice of the
global batch that the single process trains on whole, and DDP averages the slices' gradients, so the weights must
agree to float rounding (the slices' means are summed in another order), far below how far the run moved them
from INIT — which must be a real move, or the comparison says nothing. The measure is the whole weight vector's
(L2 norm of ONE − TWO over that of ONE − INIT), not the worst element: Adam divides each gradient by its own size,
so a weight whose gradient is zero but for rounding (an attention *key* bias shifts every logit of a query alike
and the softmax ignores it) takes steps of the learning rate's size in a direction set by rounding. Measured on the
CPU: 5.3e-5 for two ranks against one, and the same 5.3e-5 for one process with 1 thread against 2; a rank that
skipped the gradient average gives 1.1 (measured). Also checked: TWO's training record names
its world size, and its log was written once (by rank 0 only).
"""
import json
import sys

import numpy as np
from safetensors import safe_open


def load(path):
    with safe_open(path, framework="numpy") as f:
        return {k: f.get_tensor(k).astype(np.float64) for k in f.keys()}, f.metadata()


def main():
    init_path, one_path, two_path = sys.argv[1:4]
    init, _ = load(init_path)
    one, one_meta = load(one_path)
    two, two_meta = load(two_path)
    if set(one) != set(two) or set(one) != set(init):
        raise SystemExit(f"{two_path}: tensor names differ from {one_path} / {init_path}")
    moved = np.sqrt(sum(float(((one[k] - init[k]) ** 2).sum()) for k in one))
    apart = np.sqrt(sum(float(((one[k] - two[k]) ** 2).sum()) for k in one))
    rec_one, rec_two = json.loads(one_meta["train"]), json.loads(two_meta["train"])
    print(f"ddp: the run moved the weights by {moved:.3e} (L2); {rec_two.get('world_size')} ranks against one "
          f"process differ by {apart:.3e} ({apart / max(moved, 1e-30):.1e} of the move)")
    if moved < 1e-3:
        raise SystemExit(f"{one_path}: the weights barely moved from {init_path} ({moved:.2e}); the check is void")
    if apart > 1e-3 * moved:
        raise SystemExit(f"{two_path}: differs from {one_path} by {apart / moved:.1e} of the run's move (L2), "
                         "more than float rounding")
    if rec_one.get("world_size") != 1 or not isinstance(rec_two.get("world_size"), int) or rec_two["world_size"] < 2:
        raise SystemExit(f"{two_path}: training record world sizes {rec_one.get('world_size')} / "
                         f"{rec_two.get('world_size')}, expected 1 and >= 2")
    if rec_one["step"] != rec_two["step"] or rec_one["samples"] != rec_two["samples"]:
        raise SystemExit(f"{two_path}: {rec_two['step']} steps / {rec_two['samples']} samples against "
                         f"{rec_one['step']} / {rec_one['samples']}")
    log = two_path.removesuffix(".safetensors") + ".jsonl"
    starts = sum(1 for line in open(log) if json.loads(line).get("event") == "start")
    if starts != 1:
        raise SystemExit(f"{log}: {starts} start records, expected 1 (only rank 0 writes)")


if __name__ == "__main__":
    main()
