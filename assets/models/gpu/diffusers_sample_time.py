#!/usr/bin/env python3
"""Time diffusers' DDIM sampling loop for a tactile-derender model: the peer of `tnd sample --no-guidance`.

    python3 diffusers_sample_time.py FOLDER --samples 16 --steps 25 --runs 3 --device cuda

FOLDER is written by `tnd model export --diffusers FOLDER` (the U-Net and its DDIM scheduler: trailing spacing, the
model's prediction type). The loop is the one `tnd sample` runs without guidance: x_T ~ N(0, 1), then for each of
`--steps` DDIM timesteps (η = 0) one U-Net forward on cat([x_t, imprint]) for all samples at once and one scheduler
step. The imprint is random: the time does not depend on the values. f32, PyTorch's default math settings, no
autocast (tnd samples in f32). One untimed warm-up loop, then the median of `--runs` timed loops (the device is
synchronised before each clock read). Prints one JSON line: loop_s (median), s_per_step, and the runs.
"""
import argparse
import json
import statistics
import time

import torch
from diffusers import DDIMScheduler, UNet2DModel


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--steps", type=int, default=25)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = ap.parse_args()
    dev = torch.device(args.device)
    unet = UNet2DModel.from_pretrained(args.folder).to(dev).eval()
    sched = DDIMScheduler.from_pretrained(args.folder)
    sched.set_timesteps(args.steps)
    size = unet.config.sample_size
    g = torch.Generator(device=dev).manual_seed(args.seed)
    cond = torch.randn(args.samples, 1, size, size, generator=g, device=dev)

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)

    def loop():
        x = torch.randn(args.samples, 1, size, size, generator=g, device=dev)
        with torch.inference_mode():
            for t in sched.timesteps:
                out = unet(torch.cat([x, cond], 1), t.to(dev)).sample
                x = sched.step(out, t, x, eta=0.0).prev_sample
        return x

    loop()
    sync()
    runs = []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        x = loop()
        sync()
        runs.append(time.perf_counter() - t0)
        if not torch.isfinite(x).all():
            raise SystemExit(f"{args.folder}: the sampling loop gave non-finite values")
    med = statistics.median(runs)
    name = torch.cuda.get_device_name(dev) if dev.type == "cuda" else "cpu"
    print(json.dumps({"peer": "diffusers DDIM", "device": name, "samples": args.samples, "steps": args.steps,
                      "loop_s": med, "s_per_step": med / args.steps, "runs_s": runs, "torch": torch.__version__}))


if __name__ == "__main__":
    main()
