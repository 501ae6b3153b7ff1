"""The fault suite's command line: the parser, and the arguments resolved (defaults that depend on ``--quick``
and ``--task``, the sources' settings, the modes a foreign source cannot serve) and checked before any work; a bad
value is one line (exit status 2)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mmact_ctrl.config import MODES
from scenarios.faults.injectors import FAULTS
from scenarios.faults.settings import (
    CONTACT_MODES,
    PROG,
    QUICK_DURATION_S,
    QUICK_ONSET_S,
    QUICK_SEEDS,
    QUICK_SOURCES,
    SOURCES,
)
from scenarios.sources import source_spec_arg
from scenarios.world.tasks.registry import TASKS


def _choice(kind: str, allowed) -> callable:
    allowed = tuple(allowed)

    def parse(text: str) -> str:
        if text not in allowed:
            raise argparse.ArgumentTypeError(f"unknown {kind} {text!r}; expected one of {' '.join(allowed)}")
        return text

    return parse


class _DefaultsFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except the None of options whose default depends on --quick (their help says it)."""

    def _get_help_string(self, action):
        if action.default is None:
            return action.help
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    from scenarios.cli import OneLineErrorParser as _OneLineErrorParser
    from scenarios.cli import number as _number
    from scenarios.world.targets import KINDS as TARGET_KINDS

    p = _OneLineErrorParser(
        prog=PROG,
        description=(
            "Fault-injection suite: runs every fault (source crashes, NaN chunks, garbage tokens, spliced or late "
            "chunks, silence, perception dropout/frozen/outliers/NaN, QP and MPC fallbacks, missed ticks, a moving "
            "start, an unreachable or near-singular target) in every execution mode, with the scripted expert and "
            "the learned policy, and reports success, every safety violation, exceptions and aborts."
        ),
        epilog=(
            f"--quick: {QUICK_SEEDS} seed, {QUICK_DURATION_S:g} s episodes, onset {QUICK_ONSET_S:g} s, every fault x "
            "every mode with both sources "
            f"({len(FAULTS)} x {len(MODES)} x 2 = {len(FAULTS) * len(MODES) * 2} episodes; about 1.5 min on the 2-core "
            "machine, under 2 min); an explicit --seeds / --duration-s / --onset-s / --sources overrides it. "
            f"Faults: {' '.join(FAULTS)}."
        ),
        formatter_class=_DefaultsFormatter,
    )
    p.add_argument("--faults", nargs="+", type=_choice("fault", FAULTS), default=None, metavar="NAME",
                   help="faults to inject (default: all)")
    p.add_argument("--modes", nargs="+", type=_choice("mode", MODES), default=None, metavar="MODE",
                   help=f"execution modes (default: all: {' '.join(MODES)})")
    p.add_argument("--sources", nargs="+", type=source_spec_arg, default=None, metavar="SOURCE",
                   help="chunk sources: expert (scripted), policy (the shipped learned policy), module.path:factory or "
                        "file.py:factory (your own), ws://HOST:PORT (a policy server); default expert and policy")
    p.add_argument("--source", action="append", type=source_spec_arg, default=None, metavar="SOURCE",
                   help="one more chunk source, as in moving_target and the sweep (repeatable; joins --sources; alone "
                        "it replaces the default pair)")
    p.add_argument("--source-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword setting for the module:factory sources (repeatable; VALUE read as JSON when it parses)")
    p.add_argument("--seeds", type=_number(int, "--seeds", 1), default=None, help="seeds per cell (default 3, 1 with --quick)")
    p.add_argument("--seed", type=_number(int, "--seed", 0), default=0, help="first seed")
    p.add_argument("--target", choices=TARGET_KINDS, default="static",
                   help="how the target moves (static: every mode reaches it without a fault, so the cost of each "
                        "fault shows in every column)")
    p.add_argument("--speed", type=_number(float, "--speed", 0), default=0.2, help="target speed (m/s)")
    p.add_argument("--duration-s", type=_number(float, "--duration-s", 0, False), default=None,
                   help="episode length (s; default 5, 3 with --quick)")
    p.add_argument("--onset-s", type=_number(float, "--onset-s", 0), default=None,
                   help="fault onset (s; default 0.5, during the approach, also with --quick)")
    p.add_argument("--task", choices=TASKS, default="reach",
                   help="the task every episode runs (scenarios.world.tasks): reach, pick or insert (the expert then "
                        "is the task's; default: reach)")
    p.add_argument("--out", metavar="DIR", default="out/faults", help="output directory")
    p.add_argument("--quick", action="store_true", help="the quick suite (see below)")
    p.add_argument("--workers", type=_number(int, "--workers", 1), default=1,
                   help="parallel processes (each builds its own world and source)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def parse_args(argv: list[str] | None = None) -> tuple[argparse.Namespace, list[str], list[str]]:
    """The resolved and checked arguments, the argument list (``sys.argv[1:]`` when None) and the notes for the
    report (modes left out for a source). Exits with status 2 on a bad value."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    _select(args)
    notes = _load_sources(parser, args)
    _fill_defaults(args)
    _check(parser, args)
    return args, argv, notes


def _select(args: argparse.Namespace) -> None:
    """The faults, modes and sources to run (defaults by task)."""
    args.faults = list(dict.fromkeys(args.faults or FAULTS))
    # a contact task's study is open_loop vs hybrid (the other modes are reach's field fixes; their chunk blending
    # was not built for a gripper channel: measured, temporal_ensemble and residual press a cube into the belt)
    args.modes = list(dict.fromkeys(args.modes or (MODES if args.task == "reach" else CONTACT_MODES)))
    if args.sources is None and not args.source:  # our policy knows reach only: a contact task runs the expert
        args.sources = list(QUICK_SOURCES if args.quick else SOURCES) if args.task == "reach" else ["expert"]
    args.sources = list(dict.fromkeys((args.sources or []) + (args.source or [])))


def _load_sources(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """``args.source_args`` and ``args.unservable`` filled in; the notes on the modes left out."""
    try:
        from mmact_ctrl.sources.loader import parse_source_args

        args.source_args = parse_source_args(args.source_arg)
        args.unservable, notes = _unservable(args)
    except (ValueError, OSError, RuntimeError) as exc:  # a bad plugin, a server that is down: one line
        parser.error(str(exc).splitlines()[0])
    return notes


def _fill_defaults(args: argparse.Namespace) -> None:
    """Seeds, episode length and onset: their defaults depend on ``--quick`` and ``--task``."""
    if args.seeds is None:
        args.seeds = QUICK_SEEDS if args.quick else 3
    if args.duration_s is None:  # a contact task needs 6 s (a grasp and lift, a seat take 3-5 s)
        args.duration_s = (QUICK_DURATION_S if args.quick else 5.0) if args.task == "reach" else 6.0
    if args.onset_s is None:
        args.onset_s = QUICK_ONSET_S if args.quick else 0.5


def _check(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A bad combination is one clear line before any work."""
    if not args.onset_s < args.duration_s:
        parser.error(f"--onset-s ({args.onset_s:g}) must be earlier than the end of the episode (--duration-s "
                     f"{args.duration_s:g})")
    try:
        from mmact_ctrl.config import StackConfig

        for m in args.modes:  # a bad combination is one clear line before any work
            StackConfig(mode=m, duration_s=args.duration_s)
    except ValueError as exc:
        parser.error(str(exc))
    if "policy" in args.sources:
        from policy.inference import DEFAULT_CHECKPOINT

        if not Path(DEFAULT_CHECKPOINT).is_file():
            parser.error(f"policy checkpoint {str(DEFAULT_CHECKPOINT)!r} does not exist (use --sources expert)")


def _unservable(args) -> tuple[dict[str, tuple[str, ...]], list[str]]:
    """Per foreign source, the requested modes it cannot serve (checked on a probe built here, so a bad plugin is
    one line before any work), and a note for the report on each."""
    from mmact_ctrl.executors import make_executor
    from mmact_ctrl.sources.contract import SourceError, require_capabilities
    from scenarios.sources import SourceSettings, build_source, close_source

    skip, notes = {}, []
    for spec in args.sources:
        if spec in SOURCES:
            continue
        probe = build_source(SourceSettings(spec=spec, args=dict(args.source_args)))
        try:
            for mode in args.modes:
                try:
                    require_capabilities(probe, make_executor(mode).needs, mode)
                except SourceError as exc:
                    skip.setdefault(spec, ())
                    skip[spec] += (mode,)
                    notes.append(f"--mode {mode} left out for {spec}: {exc}")
        finally:
            close_source(probe)
    return skip, notes
