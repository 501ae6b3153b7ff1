"""Offline prediction error of the target estimator on the scene's motions, without the arm (issue 13).

Mean error (mm) of ``TargetEstimator.predict_pos_many`` 0.1 / 0.2 / 0.4 s ahead (the MPC preview reaches 0.4 s),
100 Hz, 2 mm noise, 10 % dropout, 5.6 s, seeds 0-9, after 1 s. Run from the repository root:

    python docs/perception/predict_offline.py [MODELS] [FIELD=VALUE ...]

e.g. ``python docs/perception/predict_offline.py imm,imm-ct ct_accel_noise_m_s2=0.5``.
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # this checkout's packages, not an installed copy

import numpy as np  # noqa: E402

from controllers.target_estimator import FILTER_MODELS, EstimatorConfig, TargetEstimator  # noqa: E402
from scenarios.world.targets import make_motion, target_spec  # noqa: E402

KINDS = [("circle", 0.4), ("linear", 0.2), ("accelerating", 0.3), ("jump", 0.2), ("static", 0.0), ("swerve", 0.3)]
TAUS_S = np.array([0.1, 0.2, 0.4])


def mean_errors_mm(cfg: EstimatorConfig, kind: str, speed_m_s: float, seeds=range(10)) -> np.ndarray:
    errs = []
    for seed in seeds:
        motion = make_motion(target_spec(kind, speed_m_s), seed)
        rng = np.random.default_rng(1000 + seed)
        est = TargetEstimator(cfg)
        for k in range(560):
            t = 0.01 * k
            z = motion.pos_m(t) + rng.normal(0, 0.002, 3)
            est.fuse(t, None if rng.random() < 0.1 else z)
            if t >= 1.0 and est.initialized:
                truth = np.array([motion.pos_m(t + tau) for tau in TAUS_S])
                errs.append(np.linalg.norm(est.predict_pos_many(t + TAUS_S) - truth, axis=1))
    return 1000.0 * np.mean(errs, axis=0)


def main() -> None:
    models = sys.argv[1].split(",") if len(sys.argv) > 1 else list(FILTER_MODELS)
    overrides = {}
    for arg in sys.argv[2:]:
        key, value = arg.split("=", 1)
        overrides[key] = float(value)
    for model in models:
        cfg = EstimatorConfig(model=model, **overrides)
        t0 = time.time()
        cells = [f"{kind} " + " / ".join(f"{x:.1f}" for x in mean_errors_mm(cfg, kind, speed)) for kind, speed in KINDS]
        print(f"{model:7s}", " | ".join(cells), f"({time.time() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
