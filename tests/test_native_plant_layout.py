"""The plant struct's layout, checked between the extension and the native library.

``plant_rt._cplant`` (the CPython binding) allocates the plant instance and the native
node library (``bench/nodes/native/``) steps it by its address; both compile
``plant_rt/core/`` and export ``sizeof(plant)``, its blocks' sizes and its members'
offsets (``plant_rt/core/plant_layout.h``).
:func:`bench.nodes.native._plant_native.check_plant_layout` compares them when the
library is loaded. Here: the present builds agree; a faked difference on either side,
or an extension that exports no layout, is refused with one line naming both files and
what to rebuild; the checked members are every member of ``plant`` (``plant.h``), so a
member added there and not to the list fails.
"""

from __future__ import annotations

import ctypes
import re
import shutil
from pathlib import Path

import pytest

from bench._errors import BenchError
from bench.nodes.native import _plant_native
from plant_rt import _cplant

pytestmark = pytest.mark.skipif(
    not any(shutil.which(c) for c in ("cc", "gcc")), reason="needs a C compiler"
)

PLANT_H = Path(__file__).resolve().parents[1] / "plant_rt" / "core" / "plant.h"


@pytest.fixture(scope="module")
def lib() -> ctypes.CDLL:
    return _plant_native.load_plant_lib()


def _plant_members() -> list[str]:
    """The member names of ``typedef struct {...} plant;`` in ``plant.h``, in order."""
    text = PLANT_H.read_text()
    body = re.search(r"typedef struct \{([^{}]*)\} plant;", text)
    assert body is not None, "plant.h: no typedef struct {...} plant;"
    code = re.sub(r"/\*.*?\*/", "", body.group(1), flags=re.S)
    names: list[str] = []
    for decl in code.split(";"):
        decl = decl.strip()
        if not decl:
            continue
        # "double u_al, u_be" / "double seg_a[N + 1], seg_b[N + 1]" / "void *load_ctx"
        first, *rest = re.sub(r"\[[^\]]*\]", "", decl).split(",")
        names.append(first.split()[-1].lstrip("*"))
        names += [r.strip().lstrip("*") for r in rest]
    return names


def test_the_builds_agree(lib: ctypes.CDLL) -> None:
    ext = _cplant.layout()
    own = _plant_native.library_plant_layout(lib)
    assert ext == own
    names, nums = own
    assert len(names.split(";")) == len(nums)
    # sizeof(plant) first, and every offset inside it
    assert names.split(";")[0] == "sizeof(plant)"
    offsets = [v for n, v in zip(names.split(";"), nums, strict=True) if n.startswith("offsetof")]
    assert offsets == sorted(offsets) and offsets[-1] < nums[0]
    _plant_native.check_plant_layout(lib)  # does not raise


def test_every_member_of_plant_is_checked() -> None:
    names = _cplant.layout()[0].split(";")
    checked = [n[len("offsetof(plant, ") : -1] for n in names if n.startswith("offsetof(")]
    assert checked == _plant_members()


@pytest.mark.parametrize("which", ["sizeof(plant)", "offsetof(plant, meter)", "sizeof(plant_pwm)"])
def test_a_different_number_is_refused(lib: ctypes.CDLL, which: str) -> None:
    names, nums = _cplant.layout()
    i = names.split(";").index(which)
    fake = (names, (*nums[:i], nums[i] + 8, *nums[i + 1 :]))
    with pytest.raises(BenchError) as e:
        _plant_native.check_plant_layout(lib, fake)
    line = str(e.value)
    assert "\n" not in line
    assert _cplant.__file__ in line and str(lib._name) in line
    assert f"{which} is {nums[i] + 8} against {nums[i]}" in line
    assert "make .venv/.installed" in line


def test_the_library_load_refuses_a_stale_extension(
    lib: ctypes.CDLL, monkeypatch: pytest.MonkeyPatch
) -> None:
    names, nums = _cplant.layout()
    monkeypatch.setattr(_cplant, "layout", lambda: (names, (nums[0] - 8, *nums[1:])), raising=False)
    with pytest.raises(BenchError, match=r"plant struct differs .*sizeof\(plant\)"):
        _plant_native.load_plant_lib()
    # an extension built before the layout was exported
    monkeypatch.delattr(_cplant, "layout")
    with pytest.raises(BenchError, match="exports no plant layout"):
        _plant_native.load_plant_lib()
    monkeypatch.undo()
    _plant_native.load_plant_lib()  # the real pair is accepted again
