#!/usr/bin/env python3
"""CI check (issue: meet researchers in their tools): diffusers opens a folder written by
`tnd model export --diffusers DIR` in one call each, and its output is written for `tnd model verify` to compare
with ours.

    python tests/python/diffusers_export_check.py DIR IO.safetensors
    tnd model verify --model DIR --io IO.safetensors --tol 1e-4

Checks here: UNet2DModel.from_pretrained loads every weight (diffusers raises on missing or unexpected keys), the
DDPM and DDIM schedulers load from the same folder with our prediction type, and DDIM's 25 trailing timesteps are
the ones our sampler uses (249, 239, ..., 9).
"""
import json
import sys

import torch
from diffusers import DDIMScheduler, DDPMScheduler, UNet2DModel
from safetensors.torch import save_file

folder, io_path = sys.argv[1], sys.argv[2]
unet = UNet2DModel.from_pretrained(folder)
unet.eval()
with open(f"{folder}/scheduler_config.json") as f:
    want = json.load(f)
ddpm = DDPMScheduler.from_pretrained(folder)
ddim = DDIMScheduler.from_pretrained(folder)
for s in (ddpm, ddim):
    assert s.config.prediction_type == want["prediction_type"], s.config.prediction_type
    assert s.config.num_train_timesteps == want["num_train_timesteps"]
ddim.set_timesteps(25)
assert ddim.timesteps.tolist() == list(range(249, 0, -10)), ddim.timesteps.tolist()

g = torch.Generator().manual_seed(3)
size = unet.config.sample_size
x = torch.randn(2, unet.config.in_channels, size, size, generator=g)
t = torch.tensor([5, 240], dtype=torch.int64)
with torch.inference_mode():
    y = unet(x, t).sample
save_file({"input": x, "timesteps": t, "output": y.contiguous()}, io_path)
print(f"diffusers {unet.config.in_channels}-channel UNet2DModel and both schedulers loaded from {folder}")
