"""The manuals point at things that exist: README.md, CHANGELOG.md and docs/*.md.

Checked: every relative Markdown link resolves to a file of the repository, and its
``#anchor`` (if any) to a heading of the target, with GitHub's slug rule (lower case,
punctuation other than ``-`` and ``_`` dropped, spaces to ``-``); every path written as
`` `quadsim/...` ``, `` `scripts/...` ``, `` `tests/...` ``, `` `models/...` `` or
`` `docs/...` `` exists; every dotted ``quadsim.a.b`` name is a module or package, or a
name defined at the top level of one (``def``, ``class``, an assignment or an ``__all__``
entry). CHANGELOG.md names old paths on purpose: only its links are checked.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MANUALS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")
PATH = re.compile(r"`((?:quadsim|scripts|tests|models|docs)/[\w./-]*\w)")
DOTTED = re.compile(r"\bquadsim(?:\.\w+)+")


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    return {slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", path.read_text(), re.MULTILINE)}


def defines(module: Path, name: str) -> bool:
    """``name`` is defined at the top level of ``module`` or listed in its ``__all__``."""
    pattern = (rf"^(?:def|class)\s+{re.escape(name)}\b|^{re.escape(name)}\s*[:=]"
               rf"|^\s+[\"']{re.escape(name)}[\"'],")
    return re.search(pattern, module.read_text(), re.MULTILINE) is not None


def dotted_exists(name: str) -> bool:
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:k])
        module = base.with_suffix(".py")
        if not module.is_file():
            module = base / "__init__.py"
        if module.is_file():
            rest = parts[k:]
            return not rest or (len(rest) == 1 and defines(module, rest[0]))
    return False


def _text_outside_code_blocks(path: Path) -> str:
    return re.sub(r"^```.*?^```", "", path.read_text(), flags=re.MULTILINE | re.DOTALL)


@pytest.mark.parametrize("manual", [*MANUALS, ROOT / "CHANGELOG.md"],
                         ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_resolve(manual):
    bad = []
    for link in LINK.findall(_text_outside_code_blocks(manual)):
        if re.match(r"[a-z]+:", link):
            continue
        target, _, anchor = link.partition("#")
        path = (manual.parent / target).resolve() if target else manual
        if not path.exists():
            bad.append(f"{link}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            bad.append(f"{link}: no heading with this anchor")
    assert not bad, bad


@pytest.mark.parametrize("manual", MANUALS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_paths_and_modules_exist(manual):
    text = manual.read_text()
    bad = [p for p in PATH.findall(text)
           if "*" not in p and "__pycache__" not in p and not (ROOT / p.split("::")[0]).exists()]
    bad += [name for name in DOTTED.findall(text)
            if not name.endswith(".X") and not dotted_exists(name)]   # quadsim.X: a placeholder
    assert not bad, bad


def test_slug_rule():
    """The anchor README uses for the independent benchmark, by GitHub's rule (backticks,
    slashes and dots dropped, spaces to ``-``), and docs/gap.md has that heading."""
    anchor = "independent-benchmark-benchmarksgap_benchmarkpy---independent"
    assert slug("Independent benchmark (`benchmarks/gap_benchmark.py --independent`)") == anchor
    assert anchor in anchors(ROOT / "docs" / "gap.md")
