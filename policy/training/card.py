"""The model card each stage writes beside its checkpoint (``OUT/MODEL_CARD.md``): how it was made, the final
training losses, the held-out figures and the earlier stages."""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Any


def write_model_card(path: Path, ckpt: Path, args, meta, info: dict[str, Any], history: list) -> None:
    """Write the card of checkpoint ``ckpt`` of the run ``args`` on data ``meta`` (``info``: the checkpoint's) to ``path``."""
    fig = info.get("figures", {})
    lines = [
        f"# Model card: `{ckpt.name}` (stage {args.stage})", "",
        "MM-ACT-style unified-token policy of mmact-ctrl (`policy/`): one vocabulary "
        "`[special | task + segment | text | image codes | action bins]`, one bidirectional transformer, one tied head.", "",
        "## How it was made", "",
        f"- command: `{info.get('command') or ' '.join(shlex.quote(a) for a in ['python', '-m', 'policy.train', *sys.argv[1:]])}`",
        f"- data: `{' '.join(args.data)}` ({info.get('n_samples')} samples; cameras {meta.get('camera_names')}, "
        f"{meta.get('image_size_px')} px, generator {meta.get('generator', 'scenarios.collect')})",
        f"- steps: {args.steps}, seed {args.seed}, device `{args.device}`",
        f"- wall time: {info.get('train_wall_s', info.get('wall_s', 0.0)):.1f} s (training), "
        f"checkpoint size {ckpt.stat().st_size / 1e6:.2f} MB",
    ]
    if "n_params" in info:
        lines.append(f"- model parameters: {info['n_params']:,}")
    if "train_config" in info:
        lines.append(f"- train config: `{json.dumps(info['train_config'])}`")
    if "final_losses_ema" in info:
        lines += ["", "## Final training losses (EMA, masked-token cross-entropy per task)", ""]
        lines += [f"- {k}: {v}" for k, v in info["final_losses_ema"].items()]
    lines += ["", f"## Evaluation (held-out split, split seed fixed across stages; n={fig.get('n_eval', fig.get('frames_heldout'))})", ""]
    lines += [f"- {k}: {v:.4f}" if isinstance(v, float) else f"- {k}: {v}" for k, v in fig.items()]
    lines += ["", "Metrics: action token accuracy = exact bin match after one-pass decoding; action_pos_err_m = mean "
              "Euclidean TCP position error over the chunk (m); final_waypoint_to_target_m = last waypoint vs target "
              "position; the mean-chunk baseline predicts the average expert chunk; t2i token accuracy after 8-step cosine re-masking (vs the baseline that copies the current "
              "frame's codes); mmu = exact answer match after 4-step decoding.", ""]
    if history:
        lines += ["## Earlier stages", ""]
        for h in history:
            lines.append(f"- stage {h.get('stage')}: `{h.get('command')}` -> {json.dumps(h.get('figures', {}))}")
        lines.append("")
    path.write_text("\n".join(lines))
