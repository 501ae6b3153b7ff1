"""The hybrid stack: the multi-rate loop that joins a chunk source to the control layers.

mmact_ctrl composes ``policy`` and ``controllers`` and knows the world only through the
small ``World`` protocol (``mmact_ctrl.world``), which ``scenarios`` implements.
It never imports MuJoCo or ``scenarios``.
"""
