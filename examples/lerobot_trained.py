"""A policy trained with LeRobot on one of our exports (``python -m scenarios.collect --format lerobot``), back under
the control layer, in the conventions it was trained in (read from the dataset's ``meta/info.json``: the action
space, the cameras and their size, the state's fields).

This runs in **your LeRobot environment** (LeRobot needs Python >= 3.12 and its own torch; there, ``pip install -e``
this project beside it), not in our CI:

    python -m scenarios.moving_target --source examples/lerobot_trained.py:make_source \\
        --source-arg checkpoint=outputs/act_reach/checkpoints/last/pretrained_model \\
        --source-arg dataset=/abs/path/out/reach_linear_96 --mode open_loop hybrid --target linear

or served to a machine that runs the study (``python -m scenarios.serve --source examples/lerobot_trained.py:
make_source --source-arg ...`` there, ``--source ws://HOST:8000`` here: the server declares the conventions).
"""

from __future__ import annotations

from mmact_ctrl.datasets.conventions import dataset_conventions
from mmact_ctrl.sources.lerobot import LeRobotSource


def source_for_policy(policy, dataset: str, preprocess=None, postprocess=None, device: str = "cpu",
                      name: str | None = None) -> LeRobotSource:
    """Any object with LeRobot's policy interface (``reset()``, ``predict_action_chunk(batch)``) trained on
    ``dataset``, as a chunk source in that dataset's conventions."""
    return LeRobotSource(policy, preprocess=preprocess, postprocess=postprocess, device=device, name=name,
                         **dataset_conventions(dataset).source_kwargs())


def make_source(checkpoint: str, dataset: str, device: str = "cpu") -> LeRobotSource:
    """The LeRobot checkpoint ``checkpoint`` (a ``pretrained_model`` folder of ``lerobot-train``) with its own
    pre- and post-processors (normalisation with the dataset's stats)."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    cfg = PreTrainedConfig.from_pretrained(checkpoint)
    policy = get_policy_class(cfg.type).from_pretrained(checkpoint)
    policy.to(device).eval()
    pre, post = make_pre_post_processors(cfg, pretrained_path=checkpoint)
    return source_for_policy(policy, dataset, preprocess=pre, postprocess=post, device=device, name=f"lerobot {cfg.type}")
