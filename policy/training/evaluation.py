"""The held-out figures of a stage-1/2 run: action token accuracy and error (m), t2i token accuracy, mmu answer
accuracy, the aux target's errors (m), and the figures of the states near the ball and per dataset directory."""

from __future__ import annotations

import numpy as np
import torch

from policy.bundle import PolicyBundle
from policy.decoding import decode_parallel, fill_aux, target_tokens
from policy.training.batches import build_task_batch

#: held-out frames whose expert chunk starts within this distance of the target count as "near the ball" (m).
NEAR_BALL_M = 0.06
#: the name of each figure in the results (a mean over the held-out samples), in the order they are reported
FIGURE_NAMES = {"act_tok": "action_token_acc", "act_err": "action_pos_err_m", "act_final": "final_waypoint_to_target_m",
                "act_bin1": "action_token_acc_within_1bin", "t2i": "t2i_token_acc",
                "t2i_copy": "t2i_copy_current_baseline_acc", "mmu": "mmu_answer_acc", "aux_t": "aux_ball_pos_err_m",
                "aux_prev": "aux_ball_prev_pos_err_m", "aux_disp": "aux_ball_displacement_err_m"}


@torch.no_grad()
def evaluate(bundle: PolicyBundle, data: dict[str, np.ndarray], idx: np.ndarray, tasks=("mm2a", "t2i", "mmu"),
             batch: int = 64, t2i_steps: int = 8, mmu_steps: int = 4, aux_first: bool = False) -> dict[str, float]:
    """Held-out figures: action token accuracy and error (m), t2i token accuracy, mmu answer accuracy; the aux
    target's errors (m). ``aux_first``: decode the chunk given the predicted aux target (two passes)."""
    model = bundle.model
    model.eval()
    res: dict[str, float] = {"n_eval": int(len(idx))}
    acc: dict[str, list] = {k: [] for k in FIGURE_NAMES}
    for s in range(0, len(idx), batch):
        j = idx[s : s + batch]
        if "mm2a" in tasks:
            _eval_mm2a(bundle, data, j, acc, aux_first)
        if "t2i" in tasks:
            _eval_t2i(bundle, data, j, acc, t2i_steps)
        if "mmu" in tasks:
            _eval_mmu(bundle, data, j, acc, mmu_steps)
    if "mm2a" in tasks and len(idx):
        rest = np.setdiff1d(np.arange(len(data["actions_f"])), idx)
        mean_chunk = data["actions_f"][rest if len(rest) else idx].mean(0)
        res["action_pos_err_mean_chunk_baseline_m"] = float(
            np.linalg.norm(data["actions_f"][idx][..., :3] - mean_chunk[None, :, :3], axis=-1).mean())
    for k, v in acc.items():
        if v:
            res[FIGURE_NAMES[k]] = float(np.mean(np.concatenate(v)))
    if acc["act_final"]:  # the states that decide closed-loop success: the gripper already at the ball
        res.update(_final_waypoint_figures(data, idx, np.concatenate(acc["act_final"])))
    return res


def _masked_task(bundle: PolicyBundle, data, task: str, j: np.ndarray):
    """(clean tokens, layout, query with the whole target masked) of samples ``j``."""
    clean, lay = build_task_batch(bundle, data, task, j)
    inp = clean.copy()
    inp[:, lay.target_idx] = bundle.model.vocab.mask_id
    return clean, lay, inp


def _eval_mm2a(bundle: PolicyBundle, data, j: np.ndarray, acc: dict, aux_first: bool) -> None:
    """One batch of one-pass chunk decoding (and of the aux target's prediction): appends to ``acc``."""
    model, dev = bundle.model, bundle.device
    clean, lay, inp = _masked_task(bundle, data, "mm2a", j)
    if len(lay.aux_idx):
        inp[:, lay.aux_idx] = model.vocab.mask_id
        _eval_aux(bundle, data, j, inp, lay, acc)
    query = torch.as_tensor(inp, device=dev)
    if aux_first:
        query = fill_aux(model, query, lay)
    out = target_tokens(decode_parallel(model, query, lay, 1), lay).cpu().numpy()
    truth = clean[:, lay.target_idx]
    acc["act_tok"].append((out == truth).ravel())
    acc["act_bin1"].append((np.abs(out - truth) <= 1).ravel())
    pred = bundle.action_tokenizer.decode(out.reshape(len(j), -1, 7))
    err = np.linalg.norm(pred[..., :3] - data["actions_f"][j][..., :3], axis=-1)
    acc["act_err"].append(err.ravel())
    acc["act_final"].append(np.linalg.norm(pred[:, -1, :3] - data["target_pos_m"][j], axis=-1))


def _eval_aux(bundle: PolicyBundle, data, j: np.ndarray, inp: np.ndarray, lay, acc: dict) -> None:
    """The errors (m) of the aux target predicted from the masked query ``inp``: appends to ``acc``."""
    model, dev = bundle.model, bundle.device
    h = model.hidden(torch.as_tensor(inp, device=dev), lay)
    aux_bins = model.logits(h[:, torch.as_tensor(lay.aux_idx, device=dev)], "action").argmax(-1).cpu().numpy()
    aux_pred = bundle.aux_positions_m(aux_bins.reshape(len(j), -1, 3))
    aux_true = np.stack([data["target_pos_m"][j], data["target_prev_pos_m"][j]], 1)[:, : aux_pred.shape[1]]
    err = np.linalg.norm(aux_pred - aux_true, axis=-1)
    acc["aux_t"].append(err[:, 0])
    if err.shape[1] > 1:
        acc["aux_prev"].append(err[:, 1])
        dv = (aux_pred[:, 0] - aux_pred[:, 1]) - (aux_true[:, 0] - aux_true[:, 1])
        acc["aux_disp"].append(np.linalg.norm(dv, axis=-1))


def _eval_t2i(bundle: PolicyBundle, data, j: np.ndarray, acc: dict, steps: int) -> None:
    """One batch of future-frame decoding by ``steps`` re-masking steps, and the copy-the-current-frame baseline."""
    model, dev = bundle.model, bundle.device
    clean, lay, inp = _masked_task(bundle, data, "t2i", j)
    out = target_tokens(decode_parallel(model, torch.as_tensor(inp, device=dev), lay, steps), lay).cpu().numpy()
    truth = clean[:, lay.target_idx]
    acc["t2i"].append((out == truth).ravel())
    cur = data["img"][j][:, : bundle.n_cameras].astype(np.int64).reshape(len(j), -1) + model.vocab.image_offset
    acc["t2i_copy"].append((cur == truth).ravel())


def _eval_mmu(bundle: PolicyBundle, data, j: np.ndarray, acc: dict, steps: int) -> None:
    """One batch of answer decoding by ``steps`` re-masking steps: exact matches of the answer strings."""
    model, dev = bundle.model, bundle.device
    _, lay, inp = _masked_task(bundle, data, "mmu", j)
    out = target_tokens(decode_parallel(model, torch.as_tensor(inp, device=dev), lay, steps), lay).cpu().numpy()
    lo = model.vocab.text_offset
    for row, ref in zip(out, data["answer_str"][j]):
        acc["mmu"].append(np.array([bundle.text_tokenizer.decode(row - lo).strip() == str(ref).strip()]))


def _final_waypoint_figures(data, idx: np.ndarray, final: np.ndarray) -> dict[str, float]:
    """The last waypoint's distance to the target (m) over the samples that start near the ball and per directory."""
    res: dict[str, float] = {}
    near = np.linalg.norm(data["actions_f"][idx][:, 0, :3] - data["target_pos_m"][idx], axis=-1) < NEAR_BALL_M
    res["n_eval_near"] = int(near.sum())
    if near.any():
        res["final_waypoint_to_target_near_m"] = float(final[near].mean())
    source = data["source"][idx]
    for k in np.unique(source):
        res[f"final_waypoint_to_target_m_data{int(k)}"] = float(final[source == k].mean())
    return res
