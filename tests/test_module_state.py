"""No module-level mutable state in the packages (state lives in objects the caller owns).

Every module of ``lti_motion``, ``fusion`` and ``drivers`` is imported, and each of
its globals and each attribute of the classes it defines is walked: a ``dict``,
``list``, ``set``, ``bytearray``, a writeable numpy array or an instance of a
dataclass that is not frozen, anywhere inside, is state one caller could change
under another. Tables are ``MappingProxyType``, ``tuple`` or ``frozenset``; arrays
are read-only.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import types
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lti_motion", "fusion", "drivers")
#: Class attributes the language makes: enum's ``_sunder_`` tables, ``NamedTuple``'s defaults.
MACHINERY = ("_field_defaults",)


def _modules() -> list[str]:
    names = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            names.append(".".join(parts))
    return names


def mutable_part(value: object, where: str) -> str | None:
    """The first place inside ``value`` that can be changed in place, or None."""
    if isinstance(value, (dict, list, set, bytearray)):
        return f"{where} is a {type(value).__name__}"
    if isinstance(value, np.ndarray):
        return f"{where} is a writeable array" if value.flags.writeable else None
    if isinstance(value, (tuple, frozenset)):
        return next((found for i, item in enumerate(value)
                     if (found := mutable_part(item, f"{where}[{i}]"))), None)
    if isinstance(value, types.MappingProxyType):
        return next((found for key, item in value.items()
                     if (found := mutable_part(item, f"{where}[{key!r}]"))), None)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        if not type(value).__dataclass_params__.frozen:
            return f"{where} is a {type(value).__name__}, a dataclass that is not frozen"
        return next((found for f in dataclasses.fields(value)
                     if (found := mutable_part(getattr(value, f.name), f"{where}.{f.name}"))),
                    None)
    return None


def test_the_walk_finds_mutable_parts():
    frozen = np.zeros(2)
    frozen.flags.writeable = False
    assert mutable_part(types.MappingProxyType({"a": (1, frozen)}), "T") is None
    assert mutable_part(frozenset({1, 2}), "T") is None
    assert mutable_part({"a": 1}, "T") == "T is a dict"
    assert mutable_part((1, [2]), "T") == "T[1] is a list"
    assert mutable_part(types.MappingProxyType({"a": (np.zeros(2),)}), "T") == \
        "T['a'][0] is a writeable array"


@pytest.mark.parametrize("name", _modules())
def test_no_module_level_mutable_state(name):
    module = importlib.import_module(name)
    found = []
    for attr, value in vars(module).items():
        if attr.startswith("__") or isinstance(value, types.ModuleType):
            continue
        if inspect.isclass(value) and value.__module__ == name:
            for cls_attr, cls_value in vars(value).items():
                made = cls_attr.startswith("__") or cls_attr in MACHINERY or (
                    cls_attr.startswith("_") and cls_attr.endswith("_"))
                if not made and (hit := mutable_part(cls_value, f"{attr}.{cls_attr}")):
                    found.append(hit)
        elif hit := mutable_part(value, attr):
            found.append(hit)
    assert not found, f"{name}: {found}"
