"""docs/ARCHITECTURE.md draws the path from a chunk to a torque in at most 10 hops, each a file and a function that
exist: the map is held to the code."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _functions(path: Path) -> set[str]:
    """``Class.method`` and ``function`` names defined in ``path``."""
    out = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            out.add(node.name)
        elif isinstance(node, ast.ClassDef):
            out |= {f"{node.name}.{n.name}" for n in node.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    return out


def test_the_path_from_a_chunk_to_a_torque_exists_in_at_most_10_hops():
    text = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    section = text.split("## The path from a chunk to a torque")[1].split("\n## ")[0]
    hops = re.findall(r"^\| (\d+) \| `([^`]+)` \| `([^`]+)` \|", section, flags=re.M)
    assert 3 <= len(hops) <= 10 and [int(h[0]) for h in hops] == list(range(1, len(hops) + 1))
    for _, file, function in hops:
        path = ROOT / file
        assert path.is_file(), file
        assert function in _functions(path), f"{file} has no {function}"
