"""Plug-in discovery: the registry of a package whose modules each declare a `SPEC`.

`arld_jax.agents` and `arld_jax.tasks` are such packages: a new agent or task is one module there,
and the package's `REGISTRY` (name -> spec) is built from its modules by `discover`.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Iterable
from typing import TypeVar

Spec = TypeVar("Spec")


def discover(package: str, paths: Iterable[str], kind: type[Spec]) -> dict[str, Spec]:
    """name -> spec of every module of `package` (found in `paths`, the package's folders) whose
    `SPEC` is a `kind`, in the order of the modules' names. Two modules declaring one name are an
    error naming it."""
    specs: dict[str, Spec] = {}
    for info in sorted(pkgutil.iter_modules(list(paths)), key=lambda m: m.name):
        spec = getattr(importlib.import_module(f"{package}.{info.name}"), "SPEC", None)
        if isinstance(spec, kind):
            name = spec.name  # type: ignore[attr-defined]
            if name in specs:
                raise ValueError(f"two modules of {package} declare the name {name!r}")
            specs[name] = spec
    return specs
