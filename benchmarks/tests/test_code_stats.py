"""benchmarks.code_stats on a package built here, counted by hand."""

from __future__ import annotations

from benchmarks.code_stats import levels, stats


def _package(root, files: dict[str, str]):
    pkg = root / "pkg"
    pkg.mkdir()
    for name, text in files.items():
        (pkg / f"{name}.py").write_text(text, encoding="utf-8")
    return pkg


def test_counts_of_a_small_package(tmp_path):
    pkg = _package(tmp_path, {
        "__init__": "from .a import f\n",
        "a": "from . import b\nimport numpy\n\ndef f(x, y, *args, z=1):\n    return x\n",
        "b": ("def g():\n    from .c import h\n    return h\n\n\n"
              "class K:\n    def m(self, a, b, c, d, e, f, g):\n        return a\n"),
        "c": "from pkg.d import VALUE\n\ndef h():\n    '''doc'''\n    x = 1\n    return x\n",
        "d": "VALUE = 1\n",
    })
    got = stats(pkg)
    assert got.modules == 5
    # __init__ -> a -> b -> c -> d: the function-level and the absolute import count
    assert got.arrows == 4
    assert (got.levels, got.chain) == (5, ("__init__", "a", "b", "c", "d"))
    assert got.largest_function == ("c.h", 4)
    # self not counted, *args and keyword-only not positional: m has 7, f has 2
    assert got.most_positional == ("b.m", 7)
    assert got.over_limit == 1


def test_a_cycle_is_cut_at_the_arrow_back():
    assert levels({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == (3, ("c", "a", "b"))
    assert levels({"a": set()}) == (1, ("a",))
