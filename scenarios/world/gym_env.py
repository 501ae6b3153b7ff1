"""A Gymnasium environment whose step is one chunk: ``gymnasium.make("mmact_ctrl/MovingTarget-v0", ...)``.

One ``step(action)`` is one query of the policy: the action is a chunk ``(H, 7)`` in our action space (absolute TCP
position m, rotation vector relative to the nominal grasp rad, gripper opening m; or ``(H, D)`` in the space that
``action_space_kind`` / ``gripper`` declare, ``mmact_ctrl.sources.action_space``), and the step runs the chosen
executor and the whole control layer at 1 kHz (``mmact_ctrl.runner.EpisodeRunner``, the main job's loop) until the
next query is due, the latency applied as in the main job: the chunk becomes active ``latency_ms`` after the
observation it answers.

Observation (the field's conventions, LeRobot's ``pixels`` / ``agent_pos``): ``pixels`` one uint8 ``H x W x 3``
image per camera, ``agent_pos`` the joint positions (7, rad) + gripper opening (m), ``tcp_pose`` the TCP position (m)
and rotation vector (rad), ``instruction`` the text; with ``prev_frame_gap_s > 0`` also ``pixels_prev``, the frames
that long before. The target's position is not in it (the agent must see it); ``info["observation"]`` carries the
full :class:`~mmact_ctrl.chunk.Observation` as plain fields for scripted agents (the expert reads the target from it;
:func:`as_observation` rebuilds it) and debugging.

Reward: minus the TCP-target distance (m) at the end of the step, plus ``success_bonus`` on the step the success hold
(3 cm for 0.3 s, ``mmact_ctrl.metrics``) is first met; ``terminated`` then (unless ``terminate_on_success=False``),
``truncated`` at the episode's duration. ``info`` has the step's safety counts, rejections and tick counts (ticks run,
QP failures and rescues, missed ticks, MPC failures, watchdog stops; the wall-clock tick times in
``env.unwrapped.last_tick_us``, or in ``info["tick_us"]`` with ``wall_clock_info=True``), and at
the end of the episode ``info["episode"]``: the episode's metrics as ``python -m scenarios.moving_target`` reports them. With ``task="pick"`` (any main-job switch is a keyword) the scene is the pick task's and success is its own
predicate (the instructed cube lifted 5 cm for 1 s); the reward's distance is then the TCP's to that cube.

Every keyword setting is the main job's switch of the same name (``--target`` -> ``target``, ``--replan-hz`` ->
``replan_hz``, ...): the environment builds its stack and world exactly as the main job does.
"""

from __future__ import annotations

import dataclasses
import string
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from controllers.robot_description import JointLimits
from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.controller import HybridController
from mmact_ctrl.metrics import MetricsConfig, episode_metrics
from mmact_ctrl.runner import EpisodeRunner
from mmact_ctrl.sources.action_space import ActionAdapter, ActionSpace
from policy.action_tokenizer import ActionBounds, ActionTokenizer
from policy.vocab import VocabLayout

ENV_ID = "mmact_ctrl/MovingTarget-v0"
#: the characters an instruction may hold (the observation's Text space)
INSTRUCTION_CHARSET = string.ascii_letters + string.digits + " .,;:!?'-"
INSTRUCTION_MAX_LEN = 200


class _AgentChunks:
    """The chunk source the runner calls: it answers the chunk the agent gave in ``step``."""

    def __init__(self, needs_image: bool, prev_frame_gap_s: float, token_range) -> None:
        self.needs_image = needs_image
        self.prev_frame_gap_s = prev_frame_gap_s
        self.action_token_range = token_range
        self.next: ActionChunk | None = None
        self.last_known: np.ndarray | None = None

    def plan(self, observation: Observation) -> ActionChunk | None:
        chunk, self.next = self.next, None
        return chunk

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk | None:
        """Real-time chunking: the committed prefix runs whatever the agent answers (it is frozen in its chunk)."""
        chunk = self.plan(observation)
        if chunk is None or len(known) == 0:
            return chunk
        w = chunk.waypoints.copy()
        n = min(len(known), len(w))
        w[:n] = np.asarray(known, dtype=float)[:n]
        return ActionChunk(waypoints=w, dt_s=chunk.dt_s, t0_s=chunk.t0_s, info=chunk.info)


def _main_job_args(settings: dict):
    """The main job's parsed switches with ``settings`` (keyword names = the switches, underscores) applied, so the
    environment takes the same defaults and validation (one-line ``ValueError`` naming a bad value)."""
    from scenarios.moving_target import build_parser

    parser = build_parser()
    args = parser.parse_args([])
    known = vars(args)
    for key, value in settings.items():
        if key not in known:
            raise ValueError(f"unknown setting {key!r} for {ENV_ID}; expected some of {sorted(known)}")
        setattr(args, key, value)
    return args


class MovingTargetEnv(gymnasium.Env):
    """The moving-target scene with our control layer under the agent (see the module docstring).

    Args:
        render_mode: ``None`` or ``"rgb_array"`` (``render()`` returns a 320 px frame of the first camera).
        cameras: the scene cameras of ``pixels`` (empty: no images, faster).
        image_size_px: their side, px.
        action_space_kind, gripper: the space of the agent's actions (default ours); ``horizon`` x D actions.
        horizon: waypoints per chunk H; ``chunk_dt_s`` their spacing, s (waypoint i is for t0 + (i + 1) dt).
        prev_frame_gap_s: > 0: also observe the frames that long before each query (a two-frame policy).
        success_bonus: reward added on the step the success hold is first met.
        terminate_on_success: end the episode there (False: run to the duration, as the main job does).
        wall_clock_info: also put the step's control-tick times (us, wall clock) in ``info["tick_us"]``; off by
            default because wall-clock times differ from run to run (Gymnasium's determinism check compares infos);
            they are always in ``env.unwrapped.last_tick_us``.
        **settings: the main job's switches (``target``, ``speed``, ``objects``, ``mode``, ``replan_hz``,
            ``latency_ms``, ``bins``, ``perception``, ``filter``, ``duration_s``, ``noise_m``, ``dropout``,
            ``plane_z_m``, ``instruction``, ``retarget``, ``no_mpc``, ...).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 1.0}

    def __init__(self, render_mode: str | None = None, cameras: tuple[str, ...] | list[str] = ("front",),
                 image_size_px: int = 96, action_space_kind: str = "tcp_pose", gripper: str = "width_m",
                 horizon: int = 16, chunk_dt_s: float = 0.1, prev_frame_gap_s: float = 0.0, success_bonus: float = 1.0,
                 terminate_on_success: bool = True, wall_clock_info: bool = False, **settings: Any) -> None:
        from scenarios.world.factory import make_world
        from scenarios.moving_target import make_sensor, stack_config

        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if not (isinstance(horizon, (int, np.integer)) and horizon >= 1):
            raise ValueError(f"horizon must be an int >= 1, got {horizon!r}")
        if not prev_frame_gap_s >= 0:
            raise ValueError(f"prev_frame_gap_s must be >= 0, got {prev_frame_gap_s!r}")
        self.render_mode = render_mode
        self.cameras = tuple(cameras)
        self.horizon = int(horizon)
        self.success_bonus = float(success_bonus)
        self.terminate_on_success = bool(terminate_on_success)
        self.wall_clock_info = bool(wall_clock_info)
        self.last_tick_us: dict[str, float] = {}
        self.space = ActionSpace(action_space_kind, gripper=gripper, dt_s=float(chunk_dt_s))
        args = _main_job_args(settings)
        mode = settings.get("mode", "hybrid")
        if isinstance(mode, (list, tuple)):
            raise ValueError(f"mode must be one mode name, got {mode!r}")
        self.mode = str(mode)
        self.config = stack_config(args, self.mode)  # validates (one line naming a bad value)
        self.metadata = {**self.metadata, "render_fps": float(self.config.replan_hz)}  # one frame per step
        self._args = args
        plane = 0.0 if args.plane_z_m == "auto" else float(args.plane_z_m)
        scene_cameras = self.cameras or ("front",)
        self.world = make_world(args.target, args.speed, noise_m=args.noise_m, dropout=args.dropout,
                                n_objects=args.objects or 2, plane_z_m=plane, instruction=args.instruction,
                                image_size_px=int(image_size_px), cameras=scene_cameras, task=args.task,
                                clearance_mm=args.clearance_mm)
        self.sensor = make_sensor(args, self.world, self.config.dt_s)
        self.controller = HybridController(self.config)
        self.tokenizer = (ActionTokenizer(bins=self.config.bins, token_offset=VocabLayout(action_bins=self.config.bins).action_offset)
                          if self.config.bins else None)
        token_range = None if self.tokenizer is None else (self.tokenizer.token_offset,
                                                           self.tokenizer.token_offset + self.tokenizer.bins)
        self._agent = _AgentChunks(bool(self.cameras), float(prev_frame_gap_s), token_range)
        self._adapter = ActionAdapter(self.space, self.controller.model)
        self._metrics = MetricsConfig()
        self._hold_ticks = max(1, int(round(self._metrics.success_hold_s / self.config.dt_s)))
        self.action_space = self._make_action_space()
        self.observation_space = self._make_observation_space(int(image_size_px), prev_frame_gap_s > 0)
        self._runner: EpisodeRunner | None = None
        self._over = False
        self._closed = False

    # ---- spaces ------------------------------------------------------------------------------------
    def _make_action_space(self) -> spaces.Box:
        d = self.space.dims
        if self.space.is_native:  # the tokenizer's bounds: what the action bins can represent
            b = ActionBounds()
            low, high = np.asarray(b.low, np.float32), np.asarray(b.high, np.float32)
        else:
            low, high = np.full(d, -np.pi, np.float32), np.full(d, np.pi, np.float32)
        return spaces.Box(np.tile(low, (self.horizon, 1)), np.tile(high, (self.horizon, 1)), dtype=np.float32)

    def _make_observation_space(self, size: int, with_prev: bool) -> spaces.Dict:
        img = spaces.Box(0, 255, (size, size, 3), dtype=np.uint8)
        lim = JointLimits()
        margin = 0.1  # rad: the measured joints may pass a limit slightly before the controller brings them back
        inner = {
            "agent_pos": spaces.Box(np.array([*np.add(lim.q_min_rad, -margin), 0.0], np.float32),
                                    np.array([*np.add(lim.q_max_rad, margin), 0.1], np.float32), dtype=np.float32),
            # the Panda reaches 0.86 m from its base; rotation vectors lie within pi
            "tcp_pose": spaces.Box(np.array([-1.2, -1.2, -0.5, -np.pi, -np.pi, -np.pi], np.float32),
                                   np.array([1.2, 1.2, 1.6, np.pi, np.pi, np.pi], np.float32), dtype=np.float32),
            "instruction": spaces.Text(INSTRUCTION_MAX_LEN, min_length=0, charset=INSTRUCTION_CHARSET),
        }
        if self.cameras:
            inner["pixels"] = spaces.Dict({c: img for c in self.cameras})
            if with_prev:
                inner["pixels_prev"] = spaces.Dict({c: img for c in self.cameras})
        return spaces.Dict(inner)

    # ---- the Gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """A new episode. With ``seed`` it is that seed's episode (the main job's ``--seed`` numbering: the same
        target motion and noise); without, a seed drawn from the environment's generator."""
        super().reset(seed=seed)
        if self._closed:
            raise RuntimeError("the environment is closed")
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        self._runner = EpisodeRunner(self.world, self._agent, self.controller, episode_seed, sensor=self.sensor,
                                     pause_at_queries=True)
        self._inside_run = 0
        self._succeeded = False
        self._over = False
        self._checked_ticks = 0
        self._runner.advance()  # to the first query (t = 0)
        return self._observation(), self._info(first=True)

    def step(self, action):
        runner = self._runner
        if runner is None:
            raise RuntimeError("call reset() before step()")
        if runner.done or self._over:
            raise RuntimeError("the episode is over (terminated or truncated): call reset()")
        obs = runner.pending_query
        chunk = self._chunk(action, obs)  # raises ValueError naming the problem; the episode is left as it was
        counts0 = dict(runner.monitor.counts)
        rejected0 = dict(runner.intake.rejections)
        faults0 = self._fault_counts()
        k0 = runner.k
        self._agent.next = chunk
        runner.advance()
        log = runner.log
        k1 = runner.k
        err = np.linalg.norm(log.ee_pos_m[k0:k1] - log.target_pos_m[k0:k1], axis=1)
        first_success = False
        task_report = getattr(self.world, "task_report", None)
        if task_report is not None:  # a contact task (task="pick") judges itself: its predicate, not the reach hold
            first_success = bool(task_report()["success"]) and not self._succeeded
            self._succeeded = self._succeeded or first_success
        else:
            for inside in err < self._metrics.success_radius_m:  # the success hold, tick by tick
                self._inside_run = self._inside_run + 1 if inside else 0
                if self._inside_run >= self._hold_ticks and not self._succeeded:
                    self._succeeded = first_success = True
        distance = float(err[-1]) if len(err) else float("nan")
        reward = -distance + (self.success_bonus if first_success else 0.0)
        terminated = bool(self._succeeded and self.terminate_on_success)
        truncated = bool(runner.done and not terminated)
        info = self._info()
        info.update(
            distance_m=distance,
            success=self._succeeded,
            safety={k: int(v - counts0.get(k, 0)) for k, v in runner.monitor.counts.items()},
            rejections={k: int(v - rejected0.get(k, 0)) for k, v in runner.intake.rejections.items()
                        if v - rejected0.get(k, 0)},
            ticks={"n": int(k1 - k0), **{k: int(v - faults0[k]) for k, v in self._fault_counts().items()}},
        )
        self.last_tick_us = {"median": float(np.median(log.tick_us[k0:k1])) if k1 > k0 else float("nan"),
                             "p99": float(np.percentile(log.tick_us[k0:k1], 99)) if k1 > k0 else float("nan"),
                             "max": float(np.max(log.tick_us[k0:k1])) if k1 > k0 else float("nan")}
        if self.wall_clock_info:  # wall-clock times differ from run to run: not in a deterministic info by default
            info["tick_us"] = dict(self.last_tick_us)
        info["limit_violations"] = int(sum(info["safety"].values()))
        if terminated or truncated:
            self._over = True
            m = episode_metrics(runner.finish(), self._metrics)
            m["mode"] = self.mode
            info["episode"] = m
        observation = self._observation() if not runner.done else self._final_observation()
        return observation, float(reward), terminated, truncated, info

    def render(self):
        if self.render_mode == "rgb_array":
            return np.asarray(self.world.render_video(320), dtype=np.uint8).copy()
        return None

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            getattr(self.sensor, "close", lambda: None)()
            self.world.close()

    # ---- helpers -------------------------------------------------------------------------------------
    def _fault_counts(self) -> dict[str, int]:
        """What the control layer counted so far this episode (deterministic under a seed)."""
        c, r = self.controller, self._runner
        mpc = c.mpc
        return {"qp_failures": int(c.qp.failures), "qp_rescues": int(c.qp.rescues), "missed": int(r.log.missed_ticks),
                "mpc_failures": int(mpc.failures + mpc.late) if mpc is not None else 0,
                "watchdog_stops": int(c.watchdog_stops)}

    def _chunk(self, action, obs: Observation) -> ActionChunk:
        a = np.asarray(action, dtype=np.float64)
        want = (self.horizon, self.space.dims)
        if a.shape != want:
            raise ValueError(f"action must be a chunk of shape {want} ({self.space.describe()}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
            raise ValueError(f"action contains NaN or inf (first at waypoint {bad[0]}, dim {bad[1]}): refused")
        chunk = self._adapter.to_chunk(a, obs)
        if self.tokenizer is None:
            return chunk
        waypoints, tokens, n_clipped = self.tokenizer.roundtrip(chunk.waypoints)  # the action bins, as the main job
        return ActionChunk(waypoints=waypoints, dt_s=chunk.dt_s, t0_s=chunk.t0_s, tokens=tokens, n_clipped=n_clipped,
                           info=chunk.info)

    def _observation_of(self, obs: Observation) -> dict:
        out: dict = {
            "agent_pos": np.concatenate([obs.q_rad, [obs.gripper_m]]).astype(np.float32),
            "tcp_pose": np.concatenate([obs.ee_pos_m, obs.ee_rotvec_rad]).astype(np.float32),
            "instruction": str(obs.instruction)[:INSTRUCTION_MAX_LEN],
        }
        if self.cameras:
            out["pixels"] = {c: np.array(obs.image[i], dtype=np.uint8) for i, c in enumerate(self.cameras)}
            if "pixels_prev" in self.observation_space.spaces:
                prev = obs.prev_image if obs.prev_image is not None else obs.image
                out["pixels_prev"] = {c: np.array(prev[i], dtype=np.uint8) for i, c in enumerate(self.cameras)}
        return out

    def _observation(self) -> dict:
        return self._observation_of(self._runner.pending_query)

    def _final_observation(self) -> dict:
        """The observation at the end of the episode (no query is due: it is taken now, as a query would be)."""
        from mmact_ctrl.runner import observe

        runner = self._runner
        obs = observe(self.world, self.controller, runner.t_s, with_image=bool(self.cameras))
        return self._observation_of(obs)

    def _info(self, first: bool = False) -> dict:
        runner = self._runner
        info: dict = {"t_s": float(runner.t_s)}
        if runner.pending_query is not None:  # plain arrays (comparable, copied): as_observation() rebuilds it
            info["observation"] = {f.name: (np.array(v) if isinstance(v, np.ndarray) else v)
                                   for f in dataclasses.fields(Observation)
                                   for v in (getattr(runner.pending_query, f.name),)}
        return info


def as_observation(info: dict) -> Observation:
    """The :class:`~mmact_ctrl.chunk.Observation` of a step's ``info`` (what a chunk source's ``plan`` takes: the
    scripted expert reads the target's position from it)."""
    return Observation(**info["observation"])


def register() -> None:
    """Register :data:`ENV_ID` with Gymnasium (``mmact_ctrl`` does it on import when Gymnasium is installed)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="scenarios.world.gym_env:MovingTargetEnv")
