"""Store a tnd checkpoint's weights as f16 (how the bundled models are shipped: half the size; `tnd` reads them as
f32), keeping its metadata (the `config` entry and the training settings) and adding any given as JSON.

    python3 assets/models/to_f16.py IN.safetensors OUT.safetensors ['{"weights": "raw (no EMA)"}']

Needs numpy only (the safetensors layout is read and written directly)."""
import json
import struct
import sys

import numpy as np


def main():
    src, dst = sys.argv[1], sys.argv[2]
    extra = json.loads(sys.argv[3]) if len(sys.argv) > 3 else {}
    raw = open(src, "rb").read()
    n = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + n])
    meta = header.pop("__metadata__", {})
    meta.update(extra)
    body, out = bytearray(), {}
    for name in sorted(header):
        t = header[name]
        start, end = t["data_offsets"]
        dtype = {"F32": "<f4", "F16": "<f2"}[t["dtype"]]
        a = np.frombuffer(raw[8 + n + start:8 + n + end], dtype=dtype).astype("<f2")
        out[name] = {"dtype": "F16", "shape": t["shape"], "data_offsets": [len(body), len(body) + a.nbytes]}
        body += a.tobytes()
    out["__metadata__"] = meta
    text = json.dumps(out, separators=(",", ":")).encode()
    text += b" " * ((8 - len(text) % 8) % 8)
    with open(dst, "wb") as f:
        f.write(struct.pack("<Q", len(text)) + text + bytes(body))


if __name__ == "__main__":
    main()
