"""``python -m policy.train``: the command line of the policy's training (``policy/training/``, one file per job).

The stages, the switches and an example are in ``python -m policy.train --help`` (``policy.training.cli``).
"""

from __future__ import annotations

# names other modules import from here (tests/test_policy_model.py, docs/policy3d/forget.py); their homes are in
# policy/training/
from policy.training.cli import main
from policy.training.data import eval_subset
from policy.training.evaluation import evaluate
from policy.training.losses import TASK_WEIGHT, task_loss
from policy.training.tokenize import load_tokenized

__all__ = ["TASK_WEIGHT", "eval_subset", "evaluate", "load_tokenized", "main", "task_loss"]

if __name__ == "__main__":
    main()
