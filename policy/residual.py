"""An A2C2-style learned residual (arXiv 2509.23224): a small MLP that corrects the chunk waypoint being executed.

At the perception rate (100 Hz) it sees the base waypoint the open-loop chunk asks for now, how old the chunk's
observation is, the latest target measurement(s) of the 100 Hz channel and the TCP state, and answers a bounded
task-space position correction; the 1 kHz QP tracks ``base waypoint + correction``. The run-time executor lives in
``mmact_ctrl.executors.residual``; its training loop (from arrays) in ``policy.residual_training``; the data (open-loop
rollouts) and the training command in ``scenarios.train_residual``.

The features (:func:`residual_features`, ``FEATURE_DIM`` = 17, all dimensionless, in this order):

=====  ==========================================================  ====================
index  feature                                                     scale (divided by)
=====  ==========================================================  ====================
0-2    latest measurement - base waypoint                          ``POS_SCALE_M`` m
3-5    latest measurement - TCP position                           ``POS_SCALE_M`` m
6-8    target velocity estimate (latest - earlier) / their dt      ``VEL_SCALE_M_S`` m/s
9-11   TCP velocity                                                ``VEL_SCALE_M_S`` m/s
12     age of the chunk's observation / chunk span                 1 (0 .. ~1)
13     age of the chunk's observation                              ``TIME_SCALE_S`` s
14-16  latest measurement - workspace centre ``WORKSPACE_CENTRE_M``  ``ABS_SCALE_M`` m
=====  ==========================================================  ====================

Everything but 14-16 is translation invariant; 14-16 tell the network where the target is in the workspace (the
targets turn at its walls). The network first replaces NaN by 0 and clips every feature to
``+-FEATURE_CLIP``, so any input, however large, gives a finite answer; the output squash
``c = max_correction_m * tanh(|r|) * r / |r|`` (``r`` the last layer's raw 3-vector) bounds its norm.

This module imports only numpy and torch (no MuJoCo, nothing of ``scenarios`` or ``mmact_ctrl``).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import nn

#: where the shipped residual lives.
DEFAULT_RESIDUAL_CHECKPOINT: Path = Path(__file__).resolve().parent / "checkpoints" / "residual.pt"

#: scale of the relative positions (m): the correction bound's order of magnitude.
POS_SCALE_M = 0.1
#: scale of the velocities (m/s): the targets' speeds are 0.1-0.4 m/s.
VEL_SCALE_M_S = 0.3
#: scale of the observation age (s): chunks run for up to ~1.2 s before the next one takes over.
TIME_SCALE_S = 1.0
#: centre (m) of the targets' workspace (the Panda's base frame) and its scale (m).
WORKSPACE_CENTRE_M = np.array([0.5, 0.0, 0.3])
ABS_SCALE_M = 0.15
#: every (scaled) feature is clipped to +- this before the network sees it.
FEATURE_CLIP = 10.0
#: a measurement pair closer in time than this (s) gives no velocity estimate (0).
MIN_MEAS_DT_S = 1e-3
#: the squash reaches at most this fraction of the bound, so rounding can never put a norm above it.
_BOUND_MARGIN = 1.0 - 1e-6

FEATURE_NAMES: tuple[str, ...] = (
    "meas_minus_base_x", "meas_minus_base_y", "meas_minus_base_z",
    "meas_minus_tcp_x", "meas_minus_tcp_y", "meas_minus_tcp_z",
    "meas_vel_x", "meas_vel_y", "meas_vel_z",
    "tcp_vel_x", "tcp_vel_y", "tcp_vel_z",
    "obs_age_over_span", "obs_age",
    "meas_abs_x", "meas_abs_y", "meas_abs_z",
)
FEATURE_DIM: int = len(FEATURE_NAMES)


@dataclass(frozen=True)
class ResidualConfig:
    """Attributes:
    hidden: width of every hidden layer (>= 1).
    layers: hidden layers (>= 1).
    max_correction_m: bound on the correction's norm, m (> 0, finite).
    history_s: the earlier measurement given beside the latest one is the latest one as of this long ago, s (> 0);
        the pair's difference over their capture-time difference is the target velocity estimate.
    """

    hidden: int = 128
    layers: int = 3
    max_correction_m: float = 0.15
    history_s: float = 0.1

    def __post_init__(self) -> None:
        for name in ("hidden", "layers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"ResidualConfig.{name} must be an integer >= 1, got {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("max_correction_m", "history_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"ResidualConfig.{name} must be a finite number > 0, got {value!r}")
            object.__setattr__(self, name, float(value))


def _vec(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise ValueError(f"residual_features: {name} must have shape (..., 3), got {a.shape}")
    return a


def residual_features(base_pos_m, t_since_obs_s, chunk_span_s, meas_pos_m, meas_prev_pos_m, meas_dt_s,
                      tcp_pos_m, tcp_vel_m_s) -> np.ndarray:
    """The network's input ``(..., FEATURE_DIM)`` float64, batched over the leading dimensions (broadcast).

    Args:
        base_pos_m: the base waypoint being executed now (the open-loop chunk's reference position), (..., 3) m.
        t_since_obs_s: time since the observation of the chunk that is executing, (...) s.
        chunk_span_s: that chunk's span (horizon x waypoint spacing, 1.6 s for 16 x 0.1 s), (...) s.
        meas_pos_m: the latest target measurement of the 100 Hz channel (a dropped one leaves the previous one as
            the latest), (..., 3) m.
        meas_prev_pos_m: the latest measurement as of ``ResidualConfig.history_s`` ago, (..., 3) m.
        meas_dt_s: capture time of ``meas_pos_m`` minus that of ``meas_prev_pos_m``, (...) s; below
            ``MIN_MEAS_DT_S`` (e.g. 0 when there is no earlier one yet) the velocity estimate is 0.
        tcp_pos_m: TCP position, (..., 3) m.
        tcp_vel_m_s: TCP linear velocity, (..., 3) m/s.

    The columns are listed in this module's docstring (``FEATURE_NAMES``).
    """
    base = _vec(base_pos_m, "base_pos_m")
    meas = _vec(meas_pos_m, "meas_pos_m")
    prev = _vec(meas_prev_pos_m, "meas_prev_pos_m")
    tcp = _vec(tcp_pos_m, "tcp_pos_m")
    tcp_vel = _vec(tcp_vel_m_s, "tcp_vel_m_s")
    age = np.asarray(t_since_obs_s, dtype=np.float64)
    span = np.asarray(chunk_span_s, dtype=np.float64)
    mdt = np.asarray(meas_dt_s, dtype=np.float64)
    lead = np.broadcast_shapes(base.shape[:-1], meas.shape[:-1], prev.shape[:-1], tcp.shape[:-1],
                               tcp_vel.shape[:-1], age.shape, span.shape, mdt.shape)
    out = np.empty(lead + (FEATURE_DIM,))  # written column block by column block (the executor calls it at 100 Hz)
    np.divide(meas - base, POS_SCALE_M, out=out[..., 0:3])
    np.divide(meas - tcp, POS_SCALE_M, out=out[..., 3:6])
    if mdt.ndim == 0:  # one sample: no masked division (and no errstate, which costs more than the rest)
        if mdt >= MIN_MEAS_DT_S:
            np.divide((meas - prev) / mdt, VEL_SCALE_M_S, out=out[..., 6:9])
        else:
            out[..., 6:9] = 0.0
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            ok = mdt >= MIN_MEAS_DT_S
            vel = np.where(ok[..., None], (meas - prev) / np.where(ok, mdt, 1.0)[..., None], 0.0)
        np.divide(vel, VEL_SCALE_M_S, out=out[..., 6:9])
    np.divide(tcp_vel, VEL_SCALE_M_S, out=out[..., 9:12])
    if span.ndim == 0:
        out[..., 12] = age / span if span > 0 else 0.0
    else:
        out[..., 12] = np.where(span > 0, age / np.where(span > 0, span, 1.0), 0.0)
    np.divide(age, TIME_SCALE_S, out=out[..., 13])
    np.divide(meas - WORKSPACE_CENTRE_M, ABS_SCALE_M, out=out[..., 14:17])
    return out


class _ResidualNet(nn.Module):
    """clip -> MLP (SiLU) -> norm squash; the torch twin of :meth:`ResidualPolicy.correction_m`."""

    def __init__(self, config: ResidualConfig) -> None:
        super().__init__()
        self.max_correction_m = float(config.max_correction_m)
        dims = [FEATURE_DIM] + [config.hidden] * config.layers
        self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.out = nn.Linear(dims[-1], 3)

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        h = torch.nan_to_num(x, nan=0.0, posinf=FEATURE_CLIP, neginf=-FEATURE_CLIP).clamp(-FEATURE_CLIP, FEATURE_CLIP)
        for layer in self.hidden:
            h = nn.functional.silu(layer(h))
        return self.out(h)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r = self.raw(x)
        n = r.norm(dim=-1, keepdim=True)
        # tanh(n) / n -> 1 as n -> 0; the floor keeps the division finite (r is then ~0 anyway)
        gain = torch.where(n > 1e-6, torch.tanh(n) / n.clamp_min(1e-6), 1.0 - n * n / 3.0)
        return (self.max_correction_m * _BOUND_MARGIN) * gain * r


class ResidualPolicy:
    """The residual network: torch for training, a cached numpy forward pass for the 100 Hz executor."""

    def __init__(self, config: ResidualConfig = ResidualConfig(), seed: int = 0) -> None:
        if not isinstance(config, ResidualConfig):
            raise TypeError(f"config must be a ResidualConfig, got {type(config).__name__}")
        self.config = config
        gen = torch.random.fork_rng(devices=[])
        with gen:
            torch.manual_seed(int(seed))
            self._net = _ResidualNet(config)
        self._net.eval()
        self.meta: dict = {}
        self._np: list[tuple[np.ndarray, np.ndarray]] | None = None
        self._np_version: tuple | None = None
        self._watch = False  # whether the torch weights may change under the numpy copies (torch_module handed out)

    # ---- inference ------------------------------------------------------------------
    def _weights(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """float64 numpy copies of the weights (transposed). Once :meth:`torch_module` has been handed out (it may
        be trained in place) they are refreshed whenever a torch parameter changed."""
        if self._np is not None and not self._watch:
            return self._np
        params = list(self._net.parameters())
        version = tuple((id(p), p._version) for p in params)
        if self._np is None or version != self._np_version:
            layers = list(self._net.hidden) + [self._net.out]
            self._np = [(layer.weight.detach().cpu().double().numpy().T.copy(),
                         layer.bias.detach().cpu().double().numpy().copy()) for layer in layers]
            self._np_version = version
        return self._np

    def _forward(self, h: np.ndarray) -> np.ndarray:
        weights = self._weights()
        for w, b in weights[:-1]:
            z = h @ w + b
            h = 0.5 * z * (1.0 + np.tanh(0.5 * z))  # SiLU without exp overflow
        w, b = weights[-1]
        r = h @ w + b
        bound = self.config.max_correction_m * _BOUND_MARGIN
        if r.ndim == 1:
            n = math.sqrt(float(r @ r))
            gain = math.tanh(n) / n if n > 1e-6 else 1.0 - n * n / 3.0
            return (bound * gain) * r
        n = np.sqrt(np.sum(r * r, axis=-1, keepdims=True))
        gain = np.where(n > 1e-6, np.tanh(n) / np.maximum(n, 1e-6), 1.0 - n * n / 3.0)
        return bound * gain * r

    def correction_m(self, features: np.ndarray) -> np.ndarray:
        """The correction (3,) m for one feature vector (FEATURE_DIM,), or (N, 3) for (N, FEATURE_DIM).

        Always finite with norm <= ``config.max_correction_m``, whatever the input (NaN counts as 0, the rest is
        clipped to ``+-FEATURE_CLIP``). A numpy forward pass (~20 microseconds for one sample).
        """
        x = np.asarray(features, dtype=np.float64)
        if x.ndim not in (1, 2) or x.shape[-1] != FEATURE_DIM:
            raise ValueError(f"correction_m: features must have shape ({FEATURE_DIM},) or (N, {FEATURE_DIM}), "
                             f"got {x.shape}")
        out = self._forward(np.clip(x, -FEATURE_CLIP, FEATURE_CLIP))
        if not np.isfinite(out).all():  # a NaN feature: count it as 0 (rare, so not paid for on every call)
            x = np.nan_to_num(x, nan=0.0, posinf=FEATURE_CLIP, neginf=-FEATURE_CLIP)
            out = self._forward(np.clip(x, -FEATURE_CLIP, FEATURE_CLIP))
            out = np.where(np.isfinite(out), out, 0.0)
        return out

    def __call__(self, features: np.ndarray) -> np.ndarray:
        return self.correction_m(features)

    # ---- training and storage -------------------------------------------------------------
    def torch_module(self) -> nn.Module:
        """The torch module (features (..., FEATURE_DIM) -> correction (..., 3) m); train it in place (the numpy
        copies used by :meth:`correction_m` follow)."""
        self._watch = True
        return self._net

    @property
    def n_params(self) -> int:
        return sum(p.numel() for p in self._net.parameters())

    def save(self, path, meta: dict) -> None:
        """``torch.save`` of ``{"config", "state_dict", "meta", "feature_names"}`` (meta: plain JSON values)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = json.loads(json.dumps(meta, default=_json_default))  # plain values only: loads with weights_only
        state = {k: v.detach().cpu().clone() for k, v in self._net.state_dict().items()}
        torch.save({"kind": "residual_policy", "config": asdict(self.config), "state_dict": state, "meta": meta,
                    "feature_names": list(FEATURE_NAMES)}, path)
        self.meta = meta

    @classmethod
    def load(cls, path=DEFAULT_RESIDUAL_CHECKPOINT) -> "ResidualPolicy":
        """Load a checkpoint written by :meth:`save` (``weights_only``)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"residual checkpoint not found: {path} (train one with "
                                    f"`python -m scenarios.train_residual --out {path}`)")
        try:
            payload = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as exc:  # noqa: BLE001 - torch raises assorted errors on a bad file
            raise ValueError(f"{path}: not a readable residual checkpoint ({type(exc).__name__}: {exc})") from None
        if not isinstance(payload, dict) or payload.get("kind") != "residual_policy":
            raise ValueError(f"{path}: not a residual checkpoint (no kind 'residual_policy')")
        names = payload.get("feature_names")
        if names is not None and tuple(names) != FEATURE_NAMES:
            raise ValueError(f"{path}: trained on features {names}, this code computes {list(FEATURE_NAMES)}")
        known = {f.name for f in fields(ResidualConfig)}
        config = ResidualConfig(**{k: v for k, v in payload["config"].items() if k in known})
        policy = cls(config)
        policy._net.load_state_dict(payload["state_dict"])
        policy._net.eval()
        policy.meta = dict(payload.get("meta", {}))
        return policy


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"meta value of type {type(o).__name__} is not JSON-serializable")
