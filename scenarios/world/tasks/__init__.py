"""The tasks an episode can ask of the gripper (``--task``): one file each behind one protocol (``base.Task``), named
in ``registry``: ``reach`` (today's), ``pick`` (a cube on a moving conveyor) and ``insert`` (a peg into a hole)."""
