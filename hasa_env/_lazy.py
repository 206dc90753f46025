"""The project's one lazy-import mechanism: PEP 562 attributes loaded from submodules.

A package lists names whose module is expensive to import (an optional
dependency such as Stable-Baselines3 or filterpy, or pandas / statsmodels
that most users of the package never need) and the submodule that defines
each; :func:`lazy_attributes` returns the package's ``__getattr__`` and
``__dir__``. Everything else is imported at the top of its module.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from importlib import import_module
from typing import Any

__all__ = ["lazy_attributes"]


def lazy_attributes(
    package: str, names: Mapping[str, str], eager: Iterable[str] = ()
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` loading ``names`` on first access.

    Args:
        package: the package's ``__name__``.
        names: attribute name -> module that defines it (absolute, or relative
            to ``package`` when it starts with a dot).
        eager: the names the package defines itself, for ``__dir__``.
    """
    table = dict(names)

    def __getattr__(name: str) -> Any:  # noqa: N807 - PEP 562
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(import_module(module, package), name)

    def __dir__() -> list[str]:  # noqa: N807 - PEP 562
        return sorted({*eager, *table})

    return __getattr__, __dir__
