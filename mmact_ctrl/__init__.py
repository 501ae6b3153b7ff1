"""The hybrid stack: the multi-rate loop that joins a chunk source to the control layers.

mmact_ctrl composes ``policy`` and ``controllers`` and knows the world only through the
small ``World`` protocol (``mmact_ctrl.world``), which ``scenarios`` implements.
It never imports MuJoCo or ``scenarios``.
"""


def _register_gymnasium_env() -> None:
    """``gymnasium.make("mmact_ctrl/MovingTarget-v0")`` once ``mmact_ctrl`` is imported (or with the module prefix:
    ``gymnasium.make("mmact_ctrl:mmact_ctrl/MovingTarget-v0")``). Only the entry-point *string* is registered: the
    environment (``scenarios.world.gym_env``, which builds the MuJoCo world) is imported by ``gymnasium.make``, never here."""
    import importlib.util

    if importlib.util.find_spec("gymnasium") is None:  # gymnasium is optional for everything but the environment
        return
    import gymnasium

    if "mmact_ctrl/MovingTarget-v0" not in gymnasium.registry:
        gymnasium.register(id="mmact_ctrl/MovingTarget-v0", entry_point="scenarios.world.gym_env:MovingTargetEnv")


_register_gymnasium_env()
