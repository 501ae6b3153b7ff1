"""Simulated worlds for mmact-ctrl: the MuJoCo Panda scene, target motions, the ``SimWorld``
that implements ``mmact_ctrl.world.World``, and video output.

This is the top package: it may import every other package of the project, and none of them
imports it.
"""
