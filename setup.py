"""Build of the compiled engines, ``plant_rt/_cplant.c`` with the plant's core
(``plant_rt/core/*.c``) and ``controller/_cctl.c`` with the controller's core
(``controller/core/*.c``) (the rest is in pyproject.toml).

Both cores are required: the plant's and the controller's per-period
equations exist only in C (:mod:`plant_rt._engine`, :mod:`controller._engine`),
so an install without a C compiler or Python's headers stops with one line
saying so (``tools/need-cc`` installs them).
``-ffp-contract=off`` keeps the compiler from fusing a multiply and an add
(one rounding instead of two, as on aarch64 by default), so that the C step
rounds as the tests' Python reference models do (``tests/oracle/``,
``tests/plant_reference.py``) and agrees with them bit for bit.
"""

from __future__ import annotations

import glob
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

_WHAT = {"plant_rt._cplant": "plant", "controller._cctl": "controller"}


class RequiredBuildExt(build_ext):
    """``build_ext`` that stops the install with one line when a core cannot build."""

    def run(self) -> None:
        try:
            super().run()
        except SystemExit:
            raise
        except Exception as e:
            raise SystemExit(
                f"can-hil-bench: the plant and controller cores cannot be built "
                f"({type(e).__name__}: {e}); "
                "it needs a C compiler and Python's headers: run tools/need-cc, then "
                "install again"
            ) from None

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as e:
            raise SystemExit(
                f"can-hil-bench: the {_WHAT.get(ext.name, ext.name)} core ({ext.name}) cannot be "
                f"built ({type(e).__name__}: {e}); it needs a C compiler and Python's headers: "
                "run tools/need-cc, then install again"
            ) from None


setup(
    ext_modules=[
        Extension(
            "plant_rt._cplant",
            # the binding and the portable core (plant_rt/core/, plain C99)
            ["plant_rt/_cplant.c", *sorted(str(p) for p in Path("plant_rt/core").glob("*.c"))],
            depends=sorted(str(p) for p in Path("plant_rt/core").glob("*.h")),
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
        ),
        Extension(
            "controller._cctl",
            ["controller/_cctl.c", *sorted(glob.glob("controller/core/*.c"))],
            depends=sorted(glob.glob("controller/core/*.h")),
            extra_compile_args=["-O2", "-std=c99", "-ffp-contract=off", "-fno-fast-math"],
        ),
    ],
    cmdclass={"build_ext": RequiredBuildExt},
)
