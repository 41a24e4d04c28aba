"""Every compiled kernel (numba dispatchers in ``tofpose.core.kernels`` and each stage's
``kernels`` package) keeps a short calling convention: at most ``MAX_PARAMETERS``
parameters, settings and parallel arrays travelling as records (``tofpose.core.records``
and each stage's ``records.py``), and no ``return`` of a tuple of more than
``MAX_RETURNED`` values (a longer result is a named record)."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import pkgutil
from types import ModuleType

import pytest
from numba.core.dispatcher import Dispatcher

import tofpose.core.kernels
import tofpose.stages

MAX_PARAMETERS = 12
MAX_RETURNED = 6


def _kernel_modules() -> list[ModuleType]:
    """The modules of ``tofpose.core.kernels`` and of every stage's ``kernels`` package
    (a stage without compiled code has none)."""
    packages = [tofpose.core.kernels]
    for stage in pkgutil.iter_modules(tofpose.stages.__path__):
        name = f"tofpose.stages.{stage.name}.kernels"
        if stage.ispkg and importlib.util.find_spec(name) is not None:
            packages.append(importlib.import_module(name))
    return [
        importlib.import_module(f"{package.__name__}.{module.name}")
        for package in packages
        for module in pkgutil.iter_modules(package.__path__)
    ]


MODULES = _kernel_modules()
#: (module.name, dispatcher) of every kernel defined in those modules
KERNELS = [
    (f"{module.__name__}.{name}", obj)
    for module in MODULES
    for name, obj in vars(module).items()
    if isinstance(obj, Dispatcher) and obj.py_func.__module__ == module.__name__
]


def test_the_kernels_are_found():
    """Every kernels package is walked (the core's and each stage's with compiled code)."""
    packages = {m.__name__.rsplit(".", 1)[0] for m in MODULES}
    assert "tofpose.core.kernels" in packages
    assert {"pose", "tracking", "persistence", "extraction", "matching", "ellipses"} <= {
        p.split(".")[2] for p in packages if p.startswith("tofpose.stages.")
    }
    assert len(KERNELS) > 100


@pytest.mark.parametrize("kernel", [k for _, k in KERNELS], ids=[n for n, _ in KERNELS])
def test_a_kernel_takes_at_most_twelve_parameters(kernel):
    parameters = inspect.signature(kernel.py_func).parameters
    assert len(parameters) <= MAX_PARAMETERS, (
        f"{kernel.py_func.__qualname__} takes {len(parameters)} parameters "
        f"({', '.join(parameters)}): group them into records"
    )


@pytest.mark.parametrize("module", MODULES, ids=[m.__name__ for m in MODULES])
def test_no_kernel_returns_a_tuple_of_more_than_six_values(module):
    """Any ``return`` of a tuple literal, in a kernel or a function nested in one."""
    tree = ast.parse(inspect.getsource(module))
    wide = [
        f"{module.__name__}:{node.lineno} returns {len(node.value.elts)} values"
        for node in ast.walk(tree)
        if isinstance(node, ast.Return)
        and isinstance(node.value, ast.Tuple)
        and len(node.value.elts) > MAX_RETURNED
    ]
    assert not wide, "; ".join(wide) + ": return a named record"
