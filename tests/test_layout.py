"""The package layout: commands at the top, one subpackage per pipeline stage, imports flowing
one way (a stage imports only stages before it), no import circle; every command in the
README's command table answers ``--help`` with exit 0."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "quadsim"
README = PACKAGE.parent / "README.md"

#: Pipeline stages in data-flow order; a stage may import itself and the stages before it.
#: ``identify`` comes after ``logs`` and ``gap``: identifying a vehicle from its flight logs
#: reads them with the log importers and checks and smooths them into flight states and refits
#: the drag factor with the gap's equation-error tools; no earlier stage needs it.
STAGES = ("core", "cad", "vehicle", "effects", "sim", "logs", "viewer", "gap", "identify",
          "sweep")
#: The commands (``python -m quadsim.X``); a command may import any stage, no stage a command.
COMMANDS = ("build_mjcf", "inertia_report", "identify", "openloop", "fly", "view", "convert",
            "gap", "sweep")


def _module_name(path: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    package = parts[-1] == "__init__"
    return ".".join(parts[:-1] if package else parts), package


def import_graph() -> dict[str, set[str]]:
    """Module -> quadsim modules it imports (function-level imports included)."""
    modules = {_module_name(p)[0]: p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                candidates = [target] + [f"{target}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                candidates = [a.name for a in node.names]
            else:
                continue
            for candidate in candidates:
                if not candidate.startswith("quadsim"):
                    continue
                # importing a submodule also runs its packages' __init__ (but not one's own)
                while candidate.startswith("quadsim") and candidate not in modules:
                    candidate = candidate.rpartition(".")[0]
                if candidate and candidate != name and not name.startswith(candidate + "."):
                    graph[name].add(candidate)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def _stage(module: str) -> str | None:
    """The stage of a module; None for the package itself and for the top-level command
    modules. A stage's ``__main__`` (``python -m quadsim.identify``) belongs to its stage: it
    imports only what its stage may."""
    parts = module.split(".")
    if len(parts) == 1:
        return None
    return parts[1]


def test_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycle():
    cycle = _cycle(import_graph())
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_top_level_holds_only_commands_and_stages():
    top = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__"}
    assert top <= set(COMMANDS), f"not a command at the top of quadsim/: {top - set(COMMANDS)}"
    packages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert packages <= set(STAGES), f"not a pipeline stage: {packages - set(STAGES)}"


def wrong_arrows(graph: dict[str, set[str]]) -> list[str]:
    """Every import in ``graph`` that goes back up the pipeline or into a command module."""
    rank = {stage: i for i, stage in enumerate(STAGES)}
    wrong = []
    for module, targets in graph.items():
        here = _stage(module)
        if here is None or here not in rank:      # the package itself or a command module
            continue
        for target in targets:
            there = _stage(target)
            if target.endswith(".__main__"):
                wrong.append(f"{module} imports the command {target}")
                continue
            if target == "quadsim" or there is None:
                continue
            if there not in rank:                 # a top-level command module
                wrong.append(f"{module} imports the command {target}")
            elif rank[there] > rank[here]:
                wrong.append(f"{module} ({here}) imports {target} ({there}, a later stage)")
    return sorted(wrong)


def test_a_stage_command_is_held_to_its_stage():
    """No exemption for ``__main__``: a stage's command importing a later stage is an arrow
    back up, like any other module of that stage."""
    graph = {"quadsim.effects.__main__": {"quadsim.gap.residual", "quadsim.core.errors"},
             "quadsim.gap.__main__": {"quadsim.logs.flightlog"},
             "quadsim.fly": {"quadsim.sweep.run"}}
    assert wrong_arrows(graph) == ["quadsim.effects.__main__ (effects) imports "
                                   "quadsim.gap.residual (gap, a later stage)"]


def test_imports_flow_down_the_pipeline():
    wrong = wrong_arrows(import_graph())
    assert not wrong, "; ".join(wrong)


#: top-level packages of the repository that are not in the wheel
HARNESS = ("benchmarks", "tests")


def _harness_imports(source: str) -> list[str]:
    """The modules of ``HARNESS`` that Python source ``source`` imports (any level)."""
    names: list[str] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and not node.level:
            names.append(node.module or "")
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
    return sorted(n for n in names if n.split(".")[0] in HARNESS)


def test_harness_import_finder_finds_one():
    assert _harness_imports("def f():\n    from benchmarks.synthetic import x\n"
                            "import tests.conftest\nfrom . import benchmarks\n") == \
        ["benchmarks.synthetic", "tests.conftest"]


def test_package_never_imports_the_benchmarks_or_the_tests():
    """benchmarks/ and tests/ sit beside the package in the repository, not in the wheel:
    no quadsim module imports them (function-level imports included)."""
    wrong = [f"{path.relative_to(PACKAGE.parent)} imports {name}"
             for path in sorted(PACKAGE.rglob("*.py"))
             for name in _harness_imports(path.read_text(encoding="utf-8"))]
    assert not wrong, "; ".join(wrong)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_imports(module: str, package: bool, source: str) -> list[str]:
    """Another quadsim module's private names that ``source`` (module ``module``; ``package``:
    an ``__init__``) uses: ``from quadsim.x import _y`` (any level, function-level included)
    and ``x._y`` on a quadsim module it imported (``from . import x``, ``import quadsim.x as
    x``). Each as ``"module: quadsim.x._y"``."""
    own = module if package else module.rpartition(".")[0]
    modules: dict[str, str] = {}        # local name -> quadsim module it is bound to
    found: list[str] = []
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = own.split(".")[: len(own.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("quadsim"):
                continue
            for alias in node.names:
                if _private(alias.name) and target != module:
                    found.append(f"{module}: {target}.{alias.name}")
                elif not _private(alias.name):
                    modules[alias.asname or alias.name] = f"{target}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("quadsim"):
                    modules[alias.asname or alias.name.split(".")[0]] = \
                        alias.name if alias.asname else alias.name.split(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) \
                and isinstance(node.value, ast.Name) and node.value.id in modules \
                and modules[node.value.id] != module:
            found.append(f"{module}: {modules[node.value.id]}.{node.attr}")
    return found


def test_private_import_finder_finds_each_form():
    source = ("from .fitting import _bounds, typical\n"
              "from . import collinear\n"
              "import quadsim.gap.residual as memo\n"
              "def f():\n"
              "    from ..vehicle.params import _quantity\n"
              "    return collinear._torque_text, memo._memo, typical._x, _own\n"
              "from .judge import __all__\n"
              "import numpy as np\n"
              "np._core\n")
    assert sorted(private_imports("quadsim.gap.heldout", False, source)) == [
        "quadsim.gap.heldout: quadsim.gap.collinear._torque_text",
        "quadsim.gap.heldout: quadsim.gap.fitting._bounds",
        "quadsim.gap.heldout: quadsim.gap.fitting.typical._x",
        "quadsim.gap.heldout: quadsim.gap.residual._memo",
        "quadsim.gap.heldout: quadsim.vehicle.params._quantity"]
    # a package's modules are one level down from its __init__; its own names are its own
    assert private_imports("quadsim.gap", True, "from .fitting import _b\nfrom . import _c") \
        == ["quadsim.gap: quadsim.gap.fitting._b"]
    assert private_imports("quadsim.gap.x", False, "from .x import _own\n") == []


#: private names still imported from files another branch is changing (normal: calibrate,
#: problem, reference, judge; speed: residual); each is made public when that branch merges,
#: and this list shrinks (a fixed entry fails below until it is removed here)
PENDING_PRIVATE: set[str] = set()


def test_no_module_imports_another_modules_private_names():
    """A name with a leading underscore is its module's own: no quadsim module imports one
    from another module or reads it as ``module._name`` (make it public, or move it)."""
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        module, package = _module_name(path)
        found.update(private_imports(module, package, path.read_text(encoding="utf-8")))
    assert not found - PENDING_PRIVATE, "; ".join(sorted(found - PENDING_PRIVATE))
    assert not PENDING_PRIVATE - found, f"now public, remove: {sorted(PENDING_PRIVATE - found)}"


def test_fast_path_depends_on_the_engines_not_back():
    graph = import_graph()
    for engine in ("quadsim.sim.analytic", "quadsim.sim.mujoco_engine"):
        assert not any(t.startswith("quadsim.sim.compiled") for t in graph[engine]), engine
    assert "quadsim.sim.analytic" in graph["quadsim.sim.compiled.kernel"]


def _readme_commands() -> list[str]:
    text = README.read_text(encoding="utf-8")
    table = text.split("## The commands", 1)[1].split("\n## ", 1)[0]
    return sorted(set(re.findall(r"`python -m (quadsim(?:\.\w+)+)", table)))


def test_readme_lists_every_command():
    assert [m.split(".", 1)[1] for m in _readme_commands()] == sorted(COMMANDS)


@pytest.mark.parametrize("module", _readme_commands())
def test_every_readme_command_has_help(module):
    run = subprocess.run([sys.executable, "-m", module, "--help"], cwd=PACKAGE.parent,
                         capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0, run.stderr[-500:]
    assert "usage:" in run.stdout and len(run.stdout) > 200


def test_names_that_left_the_package_are_refused_with_their_new_path():
    with pytest.raises(ImportError, match=r"quadsim\.gap\.synthetic_flight moved to "
                                          r"benchmarks\.synthetic .*from benchmarks\.synthetic "
                                          r"import synthetic_flight"):
        from quadsim.gap import synthetic_flight  # noqa: F401
    with pytest.raises(ImportError, match=r"from benchmarks\.synthetic import SensorNoise"):
        import quadsim.gap

        quadsim.gap.SensorNoise  # noqa: B018
    with pytest.raises(AttributeError):
        quadsim.gap.no_such_name  # noqa: B018
    with pytest.raises(ImportError, match=r"from benchmarks\.observe import MIN_GAIN"):
        from quadsim.gap.diagnose import MIN_GAIN  # noqa: F401
    # the modules merged into their stage (issue 43): each refused with its new module
    for old, new in (("memo", "residual"), ("per_flight", "diagnose"), ("selfcheck", "calibrate"),
                     ("plots", "page"), ("posefree", "logcheck")):
        with pytest.raises(ImportError, match=rf"quadsim\.gap\.{old} was merged into "
                                              rf"quadsim\.gap\.{new}: write `from quadsim\.gap "
                                              rf"import {new}`"):
            exec(f"from quadsim.gap import {old}")
        assert not (PACKAGE / "gap" / f"{old}.py").exists(), old
    # the modules that moved to benchmarks/ are gone from the package (an import of them is
    # ModuleNotFoundError; CHANGELOG.md names each new path)
    for gone in ("bench", "gap/synthetic.py", "logs/corrupt.py", "sim/rollout.py"):
        assert not (PACKAGE / gone).exists(), gone


@pytest.mark.parametrize("name", ["gap_benchmark", "nanodrone_benchmark", "fuzz_logs"])
def test_a_moved_script_runs_its_new_module_after_one_warning(name):
    done = subprocess.run([sys.executable, str(PACKAGE.parent / "scripts" / f"{name}.py"),
                           "--help"], capture_output=True, text=True, check=False,
                          cwd=PACKAGE.parent)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == [
        (f"warning: scripts/{name}.py moved to benchmarks/{name}.py: run python -m "
         f"benchmarks.{name} from the repository root")], done.stderr
    assert done.stdout.startswith("usage: ")
