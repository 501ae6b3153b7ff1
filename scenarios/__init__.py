"""The top package: the simulated world and the apps, by job.

- ``scenarios.world``: the MuJoCo Panda scene, ``SimWorld`` (implements ``mmact_ctrl.world.World``), target motions,
  the scripted expert, the camera sensor, the factory, videos, off-loop rendering, the viewer, the Gymnasium
  environment;
- ``scenarios.sweep``: the study (``python -m scenarios.sweep``), its tables, figures and report;
- ``scenarios.faults``: the fault suite (``python -m scenarios.faults``), its injectors and the wire's faults;
- entry points: ``moving_target`` (the main job), ``serve``, ``realtime_check``, ``collect``, ``train_residual``,
  ``safety_table``, ``gym_bench``; ``sources`` (every CLI's ``--source``) and ``served`` (a source in its own process).

It may import every other package of the project, and none of them imports it.
"""
