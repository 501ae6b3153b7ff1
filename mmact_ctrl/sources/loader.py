"""The plugin loader: ``--source module.path:factory`` (or ``path/to/file.py:factory``) with keyword settings from
repeatable ``--source-arg key=value``.

The factory is any callable returning a chunk source (``mmact_ctrl.sources.contract``). A source that declares an
``action_space`` other than ours is wrapped in :class:`~mmact_ctrl.sources.adapted.AdaptedSource`. Every failure
(a module that does not import, a missing attribute, a factory that raises, an object that is not a source) is a
:class:`~mmact_ctrl.sources.contract.SourceError` of one line that names it.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
from pathlib import Path
from typing import Callable, Iterable

from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.adapted import AdaptedSource
from mmact_ctrl.sources.contract import SourceError, check_source


def is_plugin_spec(spec: str) -> bool:
    """Whether ``spec`` names a factory (``module:factory``), not a built-in source name or a URL."""
    return ":" in spec and "://" not in spec


def parse_source_args(items: Iterable[str] | None) -> dict:
    """``["k=v", ...]`` -> ``{k: v}``; a value is read as JSON when it parses (numbers, true/false, null, lists,
    quoted strings), else kept as the plain string."""
    out: dict = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise SourceError(f"--source-arg {item!r} is not key=value (key a Python identifier)")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        out[key] = value
    return out


def _import_module(module: str, spec: str):
    if module.endswith(".py") or "/" in module:
        path = Path(module)
        if not path.is_file():
            raise SourceError(f"--source {spec}: no file {str(path)!r}")
        name = f"mmact_plugin_{path.stem}"
        loader_spec = importlib.util.spec_from_file_location(name, path)
        if loader_spec is None or loader_spec.loader is None:
            raise SourceError(f"--source {spec}: cannot load {str(path)!r} as a Python module")
        mod = importlib.util.module_from_spec(loader_spec)
        sys.modules[name] = mod  # dataclasses and pickling look a module up by name
        try:
            loader_spec.loader.exec_module(mod)
        except Exception as exc:  # noqa: BLE001 - the user's module: one line, naming it
            sys.modules.pop(name, None)
            raise SourceError(f"--source {spec}: importing {str(path)!r} raised {type(exc).__name__}: {exc}") from None
        return mod
    try:
        return importlib.import_module(module)
    except Exception as exc:  # noqa: BLE001
        raise SourceError(f"--source {spec}: cannot import module {module!r} ({type(exc).__name__}: {exc})") from None


def load_factory(spec: str) -> Callable:
    """The callable that ``spec`` (``module.path:factory`` or ``file.py:factory``) names."""
    module, sep, attr = spec.rpartition(":")
    if not sep or not module or not attr:
        raise SourceError(f"--source {spec!r} is not module.path:factory")
    mod = _import_module(module, spec)
    obj = mod
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise SourceError(f"--source {spec}: module {module!r} has no attribute {attr!r}") from None
    if not callable(obj):
        raise SourceError(f"--source {spec}: {attr!r} is a {type(obj).__name__}, not a callable that returns a source")
    return obj


def wrap_source(obj, name: str):
    """``obj`` checked against the contract, wrapped in :class:`AdaptedSource` when it declares a foreign
    ``action_space``."""
    check_source(obj, name)
    space = getattr(obj, "action_space", None)
    if space is None:
        return obj
    try:
        space = ActionSpace.from_dict(space) if isinstance(space, dict) else space
        if not isinstance(space, ActionSpace):
            raise ValueError(f"action_space must be an ActionSpace or a dict, got {type(space).__name__}")
        return AdaptedSource(obj, space)
    except ValueError as exc:
        raise SourceError(f"{name}: {exc}") from None


def load_source(spec: str, kwargs: dict | None = None):
    """Build the source that ``spec`` names, with ``kwargs`` (``--source-arg``) for its factory."""
    factory = load_factory(spec)
    try:
        obj = factory(**(kwargs or {}))
    except Exception as exc:  # noqa: BLE001 - a factory that raises: one line, naming it
        raise SourceError(f"--source {spec}: the factory raised {type(exc).__name__}: {exc}") from None
    return wrap_source(obj, f"--source {spec}")
