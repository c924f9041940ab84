"""Packaging hook: copy the shipped parameter sets (``models/``) and the CAD testbed
(``cad/``) into the wheel as ``quadsim/_shipped/{models,cad}`` (see quadsim.core.shipped).
Everything else is in pyproject.toml."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
#: folder -> patterns (a pattern's subfolder is kept: models/references/NAME.qref, the sets'
#: shipped references, quadsim.gap.reffile)
SHIPPED = {"models": ("*.toml", "*.xml", "references/*.qref"),
           "cad": ("*.toml", "*.stl", "*.step", "*.obj")}


class BuildPyWithShippedData(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):  # an editable install reads the repo folders
            return
        for folder, patterns in SHIPPED.items():
            target = Path(self.build_lib) / "quadsim" / "_shipped" / folder
            target.mkdir(parents=True, exist_ok=True)
            for pattern in patterns:
                for source in sorted((ROOT / folder).glob(pattern)):
                    copy = target / source.relative_to(ROOT / folder)
                    copy.parent.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(source, copy)


setup(cmdclass={"build_py": BuildPyWithShippedData})
