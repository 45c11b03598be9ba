"""Build of the compiled plant engine, ``plant_rt/_cplant.c`` (the rest is in pyproject.toml).

The extension is optional: on a machine without a C compiler or Python's
headers the project installs all the same, one line says that the engine
was not built, and the plant runs in pure Python (:mod:`plant_rt._engine`).
``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add
(one rounding instead of two, as on aarch64 by default), so that the C step
rounds as the Python step does and the two engines agree bit for bit.
"""

from __future__ import annotations

import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


def _not_built(e: Exception) -> None:
    print(
        f"plant_rt: the compiled plant engine was not built ({type(e).__name__}: {e}); "
        "the plant runs in pure Python",
        file=sys.stderr,
    )


class OptionalBuildExt(build_ext):
    """``build_ext`` that leaves the extension out, with one line, when it cannot build."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as e:
            _not_built(e)

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as e:
            _not_built(e)


setup(
    ext_modules=[
        Extension(
            "plant_rt._cplant",
            ["plant_rt/_cplant.c"],
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
        )
    ],
    cmdclass={"build_ext": OptionalBuildExt},
)
