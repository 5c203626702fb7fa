"""Lazy re-exports for a package's door (PEP 562): a name loads with its module on first use.

A package ``__init__`` that imports every module it re-exports makes ``import pkg``
pay for all of them (``scipy.signal`` alone costs more than the rest of the core,
``docs/benchmarks.md``), and so does any
program that needs one small module of the package, such as the command line for its
``--help``. With :func:`lazy_exports` the door lists its names in ``__all__`` as
before, and each one is imported from its module the first time it is read.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, sources: Mapping[str, Iterable[str]], public: Iterable[str],
                 ) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """A module ``__getattr__`` and ``__dir__`` that import re-exported names on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    sources : mapping of str to iterable of str
        Each module (full dotted name) and the names the package re-exports from it.
    public : iterable of str
        The package's ``__all__``: exactly the names of ``sources``, each once.

    Returns
    -------
    getattr_, dir_ : callable
        Assign them to the package's ``__getattr__`` and ``__dir__``. A name read
        once is stored in the package's namespace, as an import would store it.

    Raises
    ------
    ValueError
        If ``public`` and ``sources`` do not list the same names, or list one twice.

    Examples
    --------
    >>> getattr_, dir_ = lazy_exports("pkg", {"json": ("dumps",)}, ["dumps"])
    >>> getattr_("dumps")({"a": 1})
    '{"a": 1}'
    >>> getattr_("loads")
    Traceback (most recent call last):
    ...
    AttributeError: module 'pkg' has no attribute 'loads'
    """
    where = [(name, module) for module, names in sources.items() for name in names]
    home = dict(where)
    names = list(public)
    if len(home) != len(where) or len(set(names)) != len(names) or set(home) != set(names):
        raise ValueError(f"{package}: __all__ {sorted(names)} and the re-exported names "
                         f"{sorted(n for n, _ in where)} must be the same, each once")

    def getattr_(name: str) -> object:
        try:
            module = home[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(module), name)
        if package in sys.modules:
            setattr(sys.modules[package], name, value)
        return value

    def dir_() -> list[str]:
        loaded = vars(sys.modules[package]) if package in sys.modules else {}
        return sorted(set(loaded) | set(names))

    return getattr_, dir_
