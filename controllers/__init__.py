"""The control layers: robot model, task-space QP, MPC, Ruckig smoothing, target filter,
chunk retargeting, safety limits.

This package imports no other package of ours and never imports MuJoCo: it speaks floats
(joint states, task-space references, target measurements) and could drive a real arm.
"""
