"""The 1 kHz control layer as a chain of typed stages (``controller.HybridController``):

- :mod:`.samples`: the values between the stages (``ReferenceSample``, ``SmoothedSample``, ``TrackedReference``,
  ``TickOutput``) and the episode's ``ControllerCounters``;
- :mod:`.chunk_stage`: the executed chunk (the executor's sample + correction, the hold, the watchdog's stop);
- :mod:`.floor`: no reference below the TCP floor;
- :mod:`.smoothing`: Ruckig;
- :mod:`.plan_tracker`: the MPC's schedule, its plans, their hand-over and the bypass;
- :mod:`.view`: what an executor may read of the controller;
- :mod:`.controller`: the chain, and the QP (``controllers.qp``) at its end.
"""
