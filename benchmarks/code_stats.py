"""The size of a package's code as issue 43 counts it: modules, import levels, arrows, the
largest function and the most positional parameters.

    python -m benchmarks.code_stats [PACKAGE_DIR]      # default quadsim/gap of this checkout

Counted from the source alone (nothing is imported), so any checkout can be measured:
``git worktree add /tmp/old COMMIT && python -m benchmarks.code_stats /tmp/old/quadsim/gap``.

- ``modules``: the ``.py`` files of the package (``__init__`` and ``__main__`` included).
- ``arrows``: distinct (importer, imported) pairs among them, function-level imports included.
- ``import levels``: the modules on the longest chain of arrows (a module importing none of
  the others is level 1); an import cycle (there should be none: tests/test_layout.py) is
  cut at the arrow back to a module already on the chain.
- ``largest function``: most lines from ``def`` to its last line (docstring included).
- ``positional parameters``: a function's parameters that may be passed by position
  (``self``/``cls`` of a method and ``*args`` not counted); the most, and how many
  functions take more than 6 (the project's limit).
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Stats", "import_arrows", "levels", "stats"]

#: the project's limit on positional parameters (engineering standards)
MAX_POSITIONAL = 6


@dataclass(frozen=True)
class Stats:
    """What :func:`stats` counts (module doc)."""

    modules: int
    lines: int
    arrows: int
    levels: int
    chain: tuple[str, ...]
    largest_function: tuple[str, int]
    most_positional: tuple[str, int]
    over_limit: int

    def text(self) -> str:
        name, lines = self.largest_function
        fn, count = self.most_positional
        return "\n".join([
            f"modules: {self.modules} ({self.lines} lines)",
            f"arrows among them: {self.arrows}",
            f"import levels: {self.levels} ({' -> '.join(self.chain)})",
            f"largest function: {name}, {lines} lines",
            f"most positional parameters: {fn}, {count}; functions over {MAX_POSITIONAL}: "
            f"{self.over_limit}"])


def _target(module: str, node: ast.ImportFrom) -> str:
    """The dotted name a relative ``from . import`` in ``module`` (a package's module) names."""
    if not node.level:
        return node.module or ""
    base = module.split(".")[:-node.level]
    return ".".join(base + ([node.module] if node.module else []))


def import_arrows(package: Path) -> dict[str, set[str]]:
    """Module stem -> the package's modules it imports (function-level imports included)."""
    name = package.name
    stems = {p.stem for p in package.glob("*.py")}
    arrows: dict[str, set[str]] = {s: set() for s in stems}
    for path in package.glob("*.py"):
        module = f"{name}.{path.stem}"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                target = _target(module, node)
                names = [target] + [f"{target}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for dotted in names:
                parts = dotted.split(".")
                if name in parts:
                    rest = parts[parts.index(name) + 1:]
                    if rest and rest[0] in stems and rest[0] != path.stem:
                        arrows[path.stem].add(rest[0])
    return arrows


def levels(arrows: dict[str, set[str]]) -> tuple[int, tuple[str, ...]]:
    """The longest chain of arrows (number of modules on it, and the chain); a cycle is cut at
    the arrow back to a module already on the chain."""
    memo: dict[str, tuple[int, tuple[str, ...]]] = {}
    active: set[str] = set()

    def longest(m: str) -> tuple[int, tuple[str, ...]]:
        if m in memo:
            return memo[m]
        if m in active:                  # a cycle: cut here
            return 0, ()
        active.add(m)
        best = max((longest(n) for n in sorted(arrows[m])), default=(0, ()))
        active.discard(m)
        memo[m] = (best[0] + 1, (m,) + best[1])
        return memo[m]

    return max((longest(m) for m in sorted(arrows)), default=(0, ()))


def _positional(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> int:
    args = [a.arg for a in fn.args.posonlyargs + fn.args.args]
    static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list)
    if method and args and not static:
        args = args[1:]
    return len(args)


def stats(package: Path) -> Stats:
    """:class:`Stats` of the package folder ``package`` (module doc)."""
    files = sorted(package.glob("*.py"))
    functions: list[tuple[str, int, int]] = []        # (qualified name, lines, positional)
    lines = 0
    for path in files:
        text = path.read_text(encoding="utf-8")
        lines += len(text.splitlines())
        tree = ast.parse(text)
        owners = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                method = isinstance(owners.get(node), ast.ClassDef)
                functions.append((f"{path.stem}.{node.name}",
                                  node.end_lineno - node.lineno + 1,
                                  _positional(node, method)))
    arrows = import_arrows(package)
    depth, chain = levels(arrows)
    big = max(functions, key=lambda f: f[1])
    wide = max(functions, key=lambda f: f[2])
    return Stats(modules=len(files), lines=lines, arrows=sum(len(v) for v in arrows.values()),
                 levels=depth, chain=chain, largest_function=(big[0], big[1]),
                 most_positional=(wide[0], wide[2]),
                 over_limit=sum(1 for f in functions if f[2] > MAX_POSITIONAL))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("package", nargs="?", type=Path,
                        default=Path(__file__).resolve().parents[1] / "quadsim" / "gap")
    args = parser.parse_args(argv)
    if not args.package.is_dir():
        print(f"error: {args.package}: not a folder", file=sys.stderr)
        return 2
    print(stats(args.package).text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
