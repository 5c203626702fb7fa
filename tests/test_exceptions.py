"""Every exception class a package defines is raised somewhere in the packages.

A class nobody raises is a promise the code does not keep: a caller who writes
``except ChecksumError`` waits for an error that never comes. An exception counts as
raised when a ``raise`` statement of ``lti_motion``, ``fusion`` or ``drivers`` names it,
or names one of its subclasses (a base class is caught, not raised).
"""

from __future__ import annotations

import ast
import functools
import inspect
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lti_motion", "fusion", "drivers")


def _raised_class(exc: ast.expr) -> str:
    """The class a raise expression names: ``X``, ``X(...)``, ``mod.X(...)``, or a
    constructor classmethod's class, ``X.needed_by(...)``."""
    while True:
        if isinstance(exc, ast.Call):
            exc = exc.func
        elif isinstance(exc, ast.Attribute) and not exc.attr[:1].isupper():
            exc = exc.value                                   # X.classmethod
        else:
            break
    if isinstance(exc, ast.Attribute):
        return exc.attr
    return exc.id if isinstance(exc, ast.Name) else ""


def test_a_raise_names_its_class():
    for code in ("raise X", "raise X('m')", "raise mod.X('m')", "raise X.needed_by('m')",
                 "raise pkg.mod.X.needed_by('m') from None"):
        assert _raised_class(ast.parse(code).body[0].exc) == "X", code


@functools.cache
def raised_names() -> frozenset[str]:
    """The class names every ``raise X`` / ``raise X(...)`` / ``raise mod.X(...)`` names."""
    names = set()
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.Raise) and node.exc is not None:
                    names.add(_raised_class(node.exc))
    return frozenset(names)


def _defined(module_name: str) -> list[type[BaseException]]:
    module = __import__(module_name, fromlist=["__all__"])
    return [obj for name in module.__all__
            if inspect.isclass(obj := getattr(module, name)) and issubclass(obj, BaseException)]


EXCEPTIONS = [cls for package in PACKAGES for cls in _defined(f"{package}.exceptions")]


@pytest.mark.parametrize("cls", EXCEPTIONS, ids=lambda c: f"{c.__module__}.{c.__name__}")
def test_every_exception_class_is_raised(cls):
    raised = raised_names()
    family = [c for c in EXCEPTIONS if issubclass(c, cls)]      # itself and its subclasses
    assert any(c.__name__ in raised for c in family), (
        f"{cls.__module__}.{cls.__name__} is never raised, nor any subclass of it")
