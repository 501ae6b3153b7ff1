"""Pure learning code: the shared token space, tokenizers, the unified-token model.

This package imports no other package of ours and never imports MuJoCo.
"""
