"""Datasets out: LeRobotDataset v3.0 written and read with pyarrow and PyAV (``layout``, ``writer``, ``reader``,
``video``, ``stats``, ``roundtrip``), and the actions a frame holds (``frame_actions``). No MuJoCo here:
``scenarios.collect --format lerobot`` drives it."""
