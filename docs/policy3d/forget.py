"""mmu / t2i / action figures on the same held-out 3-D samples, before (shipped model + refreshed VQ) and after stage 2."""
import json, sys
import numpy as np, torch
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from policy.bundle import PolicyBundle
from policy.dataset import split_indices
from policy.train import evaluate, eval_subset, load_tokenized
torch.set_num_threads(1)
data_dir = sys.argv[2]  # the collected DATA
out, data, idx = {}, None, None
for name, path in (("before: shipped model, refreshed VQ (s0b)", sys.argv[3]), ("after: stage 2", sys.argv[1])):
    b = PolicyBundle.load(path)
    b.camera_names, b.frame_offsets_s = ["front", "side"], [0.0, -0.1]  # the s0b bundle's layout is the data's
    if data is None:  # both checkpoints share the VQ-VAE refresh, so the tokens are the same
        data = load_tokenized(b, data_dir, progress=False)
        _, val = split_indices(len(data["img"]), 0.1, 1234)
        idx = eval_subset(val, 256, 1234)
    out[name] = evaluate(b, data, idx)
    print(name, json.dumps({k: round(v, 4) for k, v in out[name].items() if isinstance(v, float)}), flush=True)
json.dump(out, open(sys.argv[4], "w"), indent=1)
