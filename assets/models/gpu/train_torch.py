#!/usr/bin/env python3
"""Train a tactile-derender model on a GPU with PyTorch and diffusers: the objective of `tnd train`, at GPU speed.

`tnd train` (candle, in process, CPU by default) is the product's trainer. This script exists for the few sessions
that are lent a GPU for minutes: it trains the same network on the same data with the same objective, and writes a
checkpoint that `tnd`, the workbench and `tnd model verify` load like any other. Nothing here is needed to use
tactile-derender.

Same as `tnd train` (src/model/train.rs):
  * the network is diffusers' `UNet2DModel` built from the model config stored in a tactile-derender checkpoint's
    metadata (`--init`, whose weights are loaded too, or `--config`, a JSON file, for a fresh model); its input is
    `cat([x_t, imprint])`, both normalised by the config's `tactile_derender` offsets and scales;
  * the forward process is the cosine schedule (`squaredcos_cap_v2`, T = 250, computed as schedule.rs does), t is
    drawn uniformly in 0..T-1, and the regression target is the config's prediction type (v or epsilon), MSE loss
    (optionally weighted towards the contact boundary: --boundary-weight, --boundary-px, as in `tnd train`);
  * Adam (beta 0.9 / 0.999, eps 1e-8) with an EMA of the weights; the EMA weights are what is saved.
Different, because minutes of GPU are spent best that way: batches are large (256) and drawn with replacement from
every train-split pair loaded so far (shards are read while `tnd dataset gen` is still writing more); the forward
runs under bf16 autocast; gradients are clipped to norm 1; the learning rate warms up over 200 steps and decays
(cosine, to 5 %) over the last 30 % of the wall-clock budget; the run stops at a wall-clock deadline. GPU kernels
are not bitwise deterministic, so a rerun with the same seed is close, not identical.

Several GPUs (data parallel, PyTorch DDP): launch with torchrun, e.g. `torchrun --standalone --nproc_per_node 8
train_torch.py ...` on one machine (NCCL on GPUs, gloo on the CPU). `--batch` stays the *global* batch: every rank
draws the same global batch (indices, t and noise from the one seeded generator) and trains on its slice of it, the
gradients are averaged across ranks, and rank 0 decides the learning rate and the stop from its clock and alone
writes the checkpoint and the log. So N ranks train on exactly the batches of one process with the same seed (CI
checks two CPU ranks against one process), and hyperparameters carry over unchanged. Each rank loads the train
shards itself; the pool's common prefix (the smallest count loaded on any rank) is what is drawn from.

Output (`--out NAME`): NAME.safetensors (EMA weights, f32, diffusers keys, the config and the training record in
the metadata: the format of `tnd train`'s model.safetensors), rewritten atomically every `--save-every-s` seconds
and at the end, and NAME.jsonl (one JSON line per log: step, pairs loaded, train loss, validation loss).

    python3 train_torch.py --data /tmp/train --val-data /tmp/val --init default.safetensors --out $OUT/a \\
        --deadline-s 480 --lr 2e-4 --seed 1
"""
import argparse
import glob
import json
import math
import os
import queue
import threading
import time

import numpy as np
import torch
import torch.distributed as dist
from diffusers import UNet2DModel
from safetensors import safe_open
from safetensors.torch import load_file, save_file

FORMAT = "tactile-derender UNet2DModel (diffusers keys)"


def read_metadata(path):
    """The `__metadata__` of a safetensors file."""
    with safe_open(path, framework="pt") as f:
        return f.metadata() or {}


def normalised(z, norm):
    """(imprint, target) of an open shard in model units."""
    y = (z["imprint"] - norm["imprint"]["offset_m"]) / norm["imprint"]["scale_m"]
    x0 = (z["target"] - norm["target"]["offset_m"]) / norm["target"]["scale_m"]
    return y, x0


def boundary_weights(target_m, radius_px, weight):
    """Per-pixel loss weights stressing the contact boundary, as `tnd train --boundary-weight` computes them
    (src/model/train_data.rs, contact_boundary_weights): for targets (N, 1, H, W) in metres (0 = no contact) a pixel
    whose (2r+1)^2 window, clipped at the image edge, holds both contact and no contact weighs 1 + weight, every other
    pixel 1; each image's weights are scaled to a mean of 1. Contact is a depth over 5 mm (no camera inside a sensor
    sees contact nearer; the margin absorbs the f16 rounding of the stored no-contact value)."""
    contact = (target_m > 0.005).float()
    k = 2 * radius_px + 1
    pool = torch.nn.functional.max_pool2d
    some_contact = pool(contact, k, stride=1, padding=radius_px)
    some_free = pool(1.0 - contact, k, stride=1, padding=radius_px)
    w = 1.0 + weight * some_contact * some_free
    return w / w.mean(dim=(2, 3), keepdim=True)


def cosine_alphas_cumprod(steps):
    """ᾱ_t of the squaredcos_cap_v2 schedule, as src/model/schedule.rs computes it (f64 math, f32 betas)."""
    def alpha_bar(t):
        return math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2

    betas = np.array([min(1 - alpha_bar((i + 1) / steps) / alpha_bar(i / steps), 0.999) for i in range(steps)],
                     dtype=np.float32)
    alphas = (1.0 - betas).astype(np.float64)
    return np.cumprod(alphas).astype(np.float32)


class ShardReader(threading.Thread):
    """Loads `train-*.npz` shards of a dataset directory as they appear (complete shards only: `tnd dataset gen`
    writes them as hidden temp files and renames), normalised, as float16 arrays (imprint, target)."""

    def __init__(self, root, split, norm, stop):
        super().__init__(daemon=True)
        self.root, self.split, self.norm, self.stop = root, split, norm, stop
        self.out = queue.Queue()
        self.seen = set()

    def poll(self):
        new = sorted(set(glob.glob(os.path.join(self.root, "shards", f"{self.split}-*.npz"))) - self.seen)
        for path in new:
            self.seen.add(path)
            with np.load(path) as z:
                y, x0 = normalised(z, self.norm)
            self.out.put((y.astype(np.float16), x0.astype(np.float16)))
        return len(new)

    def run(self):
        while not self.stop.is_set():
            if self.poll() == 0:
                time.sleep(1.0)


def load_split_any(root, norm, limit):
    """Up to `limit` pairs of the first non-empty split of a dataset (the validation set), as float32 arrays."""
    for split in ("train", "unseen_poses", "unseen_objects"):
        paths = sorted(glob.glob(os.path.join(root, "shards", f"{split}-*.npz")))
        if not paths:
            continue
        ys, xs = [], []
        for p in paths:
            with np.load(p) as z:
                y, x0 = normalised(z, norm)
            ys.append(y)
            xs.append(x0)
            if sum(len(y) for y in ys) >= limit:
                break
        return np.concatenate(ys)[:limit].astype(np.float32), np.concatenate(xs)[:limit].astype(np.float32)
    raise SystemExit(f"{root}: no shards")


def unet_kwargs(cfg):
    """The UNet2DModel arguments of a tactile-derender config (without our own `tactile_derender` section)."""
    return UNet2DModel.extract_init_dict({k: v for k, v in cfg.items() if k != "tactile_derender"})[0]


def build_model(args):
    if args.init:
        meta = read_metadata(args.init)
        if "config" not in meta:
            raise SystemExit(f"{args.init}: no 'config' in the safetensors metadata (not a tactile-derender model)")
        cfg = json.loads(meta["config"])
    else:
        cfg = json.load(open(args.config))
    td = cfg.get("tactile_derender", {})
    if args.prediction:
        td["prediction_type"] = args.prediction
    cfg["tactile_derender"] = td
    unet = UNet2DModel(**unet_kwargs(cfg))
    if args.init:
        unet.load_state_dict(load_file(args.init), strict=True)
    return unet, cfg


def save(path, model, cfg, record):
    state = {k: v.detach().float().cpu().contiguous() for k, v in model.state_dict().items()}
    meta = {"config": json.dumps(cfg, indent=2), "format": FORMAT, "weights": "ema",
            "step": str(record["step"]), "train": json.dumps(record)}
    tmp = f"{os.path.dirname(path) or '.'}/.{os.path.basename(path)}.tmp"
    save_file(state, tmp, metadata=meta)
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="dataset directory (its train split; may still be growing)")
    ap.add_argument("--val-data", required=True, help="validation dataset directory (never trained on)")
    ap.add_argument("--init", help="tactile-derender checkpoint to start from (config and weights)")
    ap.add_argument("--config", help="model config JSON for a fresh model (when no --init)")
    ap.add_argument("--prediction", choices=["v_prediction", "epsilon"], help="override the config's")
    ap.add_argument("--out", required=True, help="output path without extension")
    ap.add_argument("--deadline-s", type=float, required=True, help="wall-clock training budget, seconds")
    ap.add_argument("--max-steps", type=int, help="stop after this many steps even before the deadline")
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--lr", type=float, default=2e-4)
    ap.add_argument("--ema", type=float, default=0.999)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--boundary-weight", type=float, default=0.0,
                    help="extra loss weight on the contact boundary (tnd train --boundary-weight; 0: plain MSE)")
    ap.add_argument("--boundary-px", type=int, default=2, help="reach of that boundary either side of the edge, px")
    ap.add_argument("--min-pairs", type=int, default=4000, help="pairs to wait for before the first step")
    ap.add_argument("--capacity", type=int, default=600_000, help="most pairs held on the device")
    ap.add_argument("--save-every-s", type=float, default=120)
    ap.add_argument("--log-every", type=int, default=100)
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = ap.parse_args()
    if not args.init and not args.config:
        raise SystemExit("give --init CHECKPOINT or --config JSON")

    t_start = time.time()
    deadline = t_start + args.deadline_s
    # torchrun sets these; a plain `python3 train_torch.py` is one rank of one.
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    if args.batch % world:
        raise SystemExit(f"--batch {args.batch} is the global batch: it must divide among {world} ranks")
    dev = torch.device(args.device)
    if world > 1:
        if dev.type == "cuda":
            dev = torch.device("cuda", local_rank)
            torch.cuda.set_device(dev)
        dist.init_process_group("nccl" if dev.type == "cuda" else "gloo")
    lead = rank == 0
    per_rank = args.batch // world
    mine = slice(rank * per_rank, (rank + 1) * per_rank)
    torch.manual_seed(args.seed)
    torch.backends.cuda.matmul.allow_tf32 = True
    torch.backends.cudnn.allow_tf32 = True
    torch.backends.cudnn.benchmark = True
    gen = torch.Generator(device=dev).manual_seed(args.seed)

    unet, cfg = build_model(args)
    td = cfg["tactile_derender"]
    norm = {"imprint": td["imprint"], "target": td["target"]}
    steps_T = int(td.get("num_train_timesteps", 250))
    v_pred = td.get("prediction_type", "epsilon") == "v_prediction"
    unet.to(dev).train()
    # Data parallel: the wrapped module averages the gradients across ranks during backward (a no-op wrapper is not
    # used for one rank, so that single-GPU runs are the code path they always were).
    net = torch.nn.parallel.DistributedDataParallel(unet) if world > 1 else unet
    ema = UNet2DModel(**unet_kwargs(cfg)).to(dev).eval()
    ema.load_state_dict(unet.state_dict())
    for p in ema.parameters():
        p.requires_grad_(False)
    params = list(unet.parameters())
    ema_params = list(ema.parameters())
    fused = dev.type == "cuda"
    opt = torch.optim.Adam(params, lr=args.lr, betas=(0.9, 0.999), eps=1e-8, fused=fused)
    n_params = sum(p.numel() for p in params)

    ab = torch.tensor(cosine_alphas_cumprod(steps_T), device=dev)
    sa_all, sb_all = ab.sqrt(), (1 - ab).sqrt()

    size = int(cfg["sample_size"])
    vy, vx = load_split_any(args.val_data, norm, 1024)
    vy, vx = torch.from_numpy(vy).to(dev)[:, None], torch.from_numpy(vx).to(dev)[:, None]
    vgen = torch.Generator(device=dev).manual_seed(12345)
    vt = torch.randint(0, steps_T, (len(vy),), generator=vgen, device=dev)
    veps = torch.randn(vx.shape, generator=vgen, device=dev)

    pool_y = torch.empty((args.capacity, 1, size, size), dtype=torch.float16, device=dev)
    pool_x = torch.empty_like(pool_y)
    loaded = 0
    stop = threading.Event()
    reader = ShardReader(args.data, "train", norm, stop)
    reader.start()

    def drain():
        nonlocal loaded
        while True:
            try:
                y, x = reader.out.get_nowait()
            except queue.Empty:
                return
            k = min(len(y), args.capacity - loaded)
            if k <= 0:
                return
            pool_y[loaded:loaded + k, 0] = torch.from_numpy(y[:k]).to(dev)
            pool_x[loaded:loaded + k, 0] = torch.from_numpy(x[:k]).to(dev)
            loaded += k

    while loaded < args.min_pairs:
        if time.time() > deadline:
            raise SystemExit(f"{args.data}: fewer than {args.min_pairs} train pairs before the deadline")
        drain()
        time.sleep(0.5)

    def common(value, op):
        """`value` reduced over the ranks (itself for one rank)."""
        if world == 1:
            return value
        v = torch.tensor([float(value)], dtype=torch.float64, device=dev)
        dist.all_reduce(v, op=op)
        return v.item()

    def drawable():
        """Pairs every rank holds: the batch is drawn from that common prefix of the pools."""
        return int(common(loaded, dist.ReduceOp.MIN))

    pool_n = drawable()
    t_train = time.time()

    log = open(args.out + ".jsonl", "a") if lead else None

    def emit(rec):
        if not lead:
            return
        log.write(json.dumps(rec) + "\n")
        log.flush()
        print(json.dumps(rec), flush=True)

    def val_loss():
        total = 0.0
        with torch.no_grad(), torch.autocast(dev.type, dtype=torch.bfloat16, enabled=dev.type == "cuda"):
            for i in range(0, len(vy), 256):
                x0, y, t, e = vx[i:i + 256], vy[i:i + 256], vt[i:i + 256], veps[i:i + 256]
                sa, sb = sa_all[t].view(-1, 1, 1, 1), sb_all[t].view(-1, 1, 1, 1)
                xt = sa * x0 + sb * e
                tgt = sa * e - sb * x0 if v_pred else e
                pred = ema(torch.cat([xt, y], 1), t).sample.float()
                total += float(((pred - tgt) ** 2).mean()) * len(x0)
        return total / len(vy)

    def record(step, final=False):
        return {"trainer": "assets/models/gpu/train_torch.py", "step": step, "batch": args.batch, "lr": args.lr,
                "ema": args.ema, "seed": args.seed,
                "boundary_weight": args.boundary_weight, "boundary_px": args.boundary_px, "init": os.path.basename(args.init) if args.init else None,
                "prediction": td.get("prediction_type"), "pairs_loaded": pool_n, "samples": step * args.batch,
                "wall_s": round(time.time() - t_start, 1), "final": final, "parameters": n_params,
                "device": (torch.cuda.get_device_name(dev) if dev.type == "cuda" else "cpu")
                + (f" x{world}" if world > 1 else ""), "world_size": world, "torch": torch.__version__}

    if lead:
        emit({"event": "start", "parameters": n_params, "pairs_loaded": pool_n, "val_loss": val_loss(),
              "wait_s": round(t_train - t_start, 1), "world_size": world})
    step, last_save, loss_acc, loss_n = 0, time.time(), 0.0, 0
    warmup = 200
    while True:
        now = time.time()
        frac = (now - t_train) / max(deadline - t_train, 1e-9)
        if world > 1:
            # Rank 0's clock decides the stop and the learning rate (every rank takes the same steps).
            clock = torch.tensor([frac], dtype=torch.float64, device=dev)
            dist.broadcast(clock, 0)
            frac = clock.item()
        if frac >= 1.0 or (args.max_steps is not None and step >= args.max_steps):
            break
        lr = args.lr * min(1.0, (step + 1) / warmup)
        if frac > 0.7:
            lr *= 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * (frac - 0.7) / 0.3))
        for g in opt.param_groups:
            g["lr"] = lr
        if step % 50 == 0:
            drain()
            pool_n = drawable()
        # The global batch, drawn alike on every rank; each trains on its slice (all of it for one rank).
        idx = torch.randint(0, pool_n, (args.batch,), generator=gen, device=dev)
        t = torch.randint(0, steps_T, (args.batch,), generator=gen, device=dev)
        eps = torch.randn((args.batch, 1, size, size), generator=gen, device=dev)
        idx, t, eps = idx[mine], t[mine], eps[mine]
        x0, y = pool_x[idx].float(), pool_y[idx].float()
        sa, sb = sa_all[t].view(-1, 1, 1, 1), sb_all[t].view(-1, 1, 1, 1)
        xt = sa * x0 + sb * eps
        tgt = sa * eps - sb * x0 if v_pred else eps
        with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=dev.type == "cuda"):
            pred = net(torch.cat([xt, y], 1), t).sample
        sq = (pred.float() - tgt) ** 2
        if args.boundary_weight > 0:
            raw = x0 * norm["target"]["scale_m"] + norm["target"]["offset_m"]
            sq = sq * boundary_weights(raw, args.boundary_px, args.boundary_weight)
        loss = sq.mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        opt.step()
        d = min(args.ema, (1 + step) / (10 + step))
        torch._foreach_lerp_(ema_params, [p.detach() for p in params], 1 - d)
        step += 1
        loss_acc += loss.detach()
        loss_n += 1
        if step % args.log_every == 0:
            mean = common(float(loss_acc) / loss_n, dist.ReduceOp.SUM) / world
            emit({"step": step, "lr": lr, "loss": mean, "pairs_loaded": pool_n,
                  "wall_s": round(time.time() - t_start, 1)})
            loss_acc, loss_n = 0.0, 0
        if lead and time.time() - last_save > args.save_every_s:
            emit({"step": step, "val_loss": val_loss(), "wall_s": round(time.time() - t_start, 1)})
            save(args.out + ".safetensors", ema, cfg, record(step))
            last_save = time.time()
    stop.set()
    if lead:
        emit({"event": "end", "step": step, "val_loss": val_loss(), "pairs_loaded": pool_n,
              "samples": step * args.batch, "wall_s": round(time.time() - t_start, 1)})
        save(args.out + ".safetensors", ema, cfg, record(step, final=True))
    if world > 1:
        dist.barrier()
        dist.destroy_process_group()


if __name__ == "__main__":
    main()
