"""Where the shipped data live: the built-in parameter sets (``models/``) and the CAD testbed
(``cad/``), in a repository checkout and in an installed wheel alike.

In the repository the two folders sit next to the package (``models/``, ``cad/``) and are
used in place, so ``python -m quadsim.build_mjcf cad/`` and ``--model physical`` work as
they always did. A wheel (``pip install .`` without ``-e``) carries copies of both inside
the package, at ``quadsim/_shipped/models`` and ``quadsim/_shipped/cad`` (put there by
``setup.py``'s ``build_py`` step; ``MANIFEST.in`` puts them into the sdist), and the same
relative layout, so a parameter set's ``from_cad = { path = "../cad" }`` still resolves.

Example::

    >>> from quadsim.core.shipped import shipped_dir
    >>> (shipped_dir("models") / "physical.toml").is_file()
    True
"""

from __future__ import annotations

from pathlib import Path

#: The shipped data folders, by name.
SHIPPED = ("models", "cad")

_PACKAGE = Path(__file__).resolve().parents[1]


def shipped_dir(name: str) -> Path:
    """The folder of shipped data ``name`` (``"models"`` or ``"cad"``): the installed copy
    inside the package when there is one, else the repository's folder beside the package."""
    if name not in SHIPPED:
        raise ValueError(f"unknown shipped folder {name!r}; valid: {', '.join(SHIPPED)}")
    installed = _PACKAGE / "_shipped" / name
    return installed if installed.is_dir() else _PACKAGE.parent / name


def is_installed_copy(folder: Path) -> bool:
    """True when ``folder`` lies inside an installed package (a wheel's data: never write
    there), False in a repository checkout."""
    return (_PACKAGE / "_shipped") in Path(folder).resolve().parents
