"""Training of the unified-token policy, one file per job (the command line is ``python -m policy.train``).

- ``tokenize``: a dataset's frames and strings as token arrays, and the checks that data fits a checkpoint
  (shared with ``policy.token_cache``; it imports nothing else of this package).
- ``data``: the token arrays of a run (from ``--data`` or ``--tokens-cache``), the data's meta, sampling weights,
  the evaluation subset.
- ``batches``: one task's clean query, the MaskGIT masking, known prefixes.
- ``losses``: the masked-token loss of a task (and of the aux target).
- ``evaluation``: the held-out figures.
- ``stage0``: the tokenizers (BPE, VQ-VAE); ``stage12_setup`` and ``stage12``: the model's stages 1/2 (the bundle
  and train config of a run, then the loop).
- ``card``: the model card; ``cli``: the argument parser and ``main``.

This ``__init__`` imports nothing, so ``policy.token_cache`` can import ``policy.training.tokenize`` without
pulling in the modules that import it.
"""
