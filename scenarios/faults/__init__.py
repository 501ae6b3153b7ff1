"""The fault suite (``python -m scenarios.faults``): the suite and its report (``suite``), one injector per fault
(``injectors``), and the wire's faults, the source served on 127.0.0.1 (``wire``)."""

from scenarios.faults.injectors import FAULTS, FaultSpec, inject, run_fault_episode
from scenarios.faults.suite import PROG, SOURCES, build_parser, main, recovery_time_s, run_cell, run_suite

__all__ = ["FAULTS", "FaultSpec", "inject", "run_fault_episode", "PROG", "SOURCES", "build_parser", "main",
           "recovery_time_s", "run_cell", "run_suite"]
