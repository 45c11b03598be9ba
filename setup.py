"""Build of the compiled engines, ``plant_rt/_cplant.c`` and ``controller/_cctl.c`` (the binding
of the portable controller core, ``controller/core/*.c``)
(the rest is in pyproject.toml).

The extensions are optional: on a machine without a C compiler or Python's
headers the project installs all the same, one line per engine says that it
was not built, and the plant and the controller run in pure Python
(:mod:`plant_rt._engine`, :mod:`controller._engine`).
``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add
(one rounding instead of two, as on aarch64 by default), so that the C step
rounds as the Python step does and the two engines agree bit for bit.
"""

from __future__ import annotations

import glob
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

_WHAT = {
    "plant_rt._cplant": ("plant_rt", "plant"),
    "controller._cctl": ("controller", "controller"),
}


def _not_built(e: Exception, name: str | None = None) -> None:
    pkg, what = _WHAT.get(name or "", ("can-hil-bench", "plant and controller"))
    print(
        f"{pkg}: the compiled {what} engine was not built ({type(e).__name__}: {e}); "
        f"the {what} runs in pure Python",
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
            _not_built(e, ext.name)


setup(
    ext_modules=[
        Extension(
            "plant_rt._cplant",
            ["plant_rt/_cplant.c"],
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
        ),
        Extension(
            "controller._cctl",
            ["controller/_cctl.c", *sorted(glob.glob("controller/core/*.c"))],
            depends=sorted(glob.glob("controller/core/*.h")),
            extra_compile_args=["-O2", "-std=c99", "-ffp-contract=off", "-fno-fast-math"],
        ),
    ],
    cmdclass={"build_ext": OptionalBuildExt},
)
