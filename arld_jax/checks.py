"""Validation helpers shared by `config.validate` and the agents' own checks.

Every check raises `ValueError` naming the Config field, its value and what is allowed, before
anything compiles (STYLE.md habit 1). A leaf module: the agents import it without importing
`config` (which imports the agents' registry).
"""

from __future__ import annotations

from typing import Any, NoReturn


def fail(name: str, value: Any, allowed: str) -> NoReturn:
    raise ValueError(f"Config.{name} = {value!r} is invalid: allowed {allowed}.")


def is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def choice(cfg: Any, name: str, options: tuple[str, ...]) -> None:
    value = getattr(cfg, name)
    if value not in options:
        fail(name, value, "one of " + ", ".join(repr(o) for o in options))


def int_at_least(cfg: Any, names: tuple[str, ...], low: int) -> None:
    for name in names:
        value = getattr(cfg, name)
        if not is_int(value) or value < low:
            fail(name, value, f"an integer >= {low}")


def non_negative(cfg: Any, names: tuple[str, ...]) -> None:
    for name in names:
        if not getattr(cfg, name) >= 0:
            fail(name, getattr(cfg, name), ">= 0")


def positive(cfg: Any, names: tuple[str, ...]) -> None:
    for name in names:
        if not getattr(cfg, name) > 0:
            fail(name, getattr(cfg, name), "> 0")
