"""The words for a bad value of a numeric option: the option, the value given, what to give.

typer's own are pydantic's (``Input should be greater than or equal to 1``) or click's,
under a usage block, without the value or a fix; :func:`number_message` says it as the
package's other errors do (``--trials takes a whole number of at least 1, not '-3'; give
e.g. --trials 1``). The command class of :mod:`._app` prints it as an ``error:`` line.
"""

from __future__ import annotations

from typing import Any

__all__ = ["number_message"]


def _bounds(param: Any) -> tuple[Any, Any]:
    """An option's least and greatest value (typer's ``min``/``max``, or click's range type)."""
    for owner in (param, getattr(param, "type", None)):
        low, high = getattr(owner, "min", None), getattr(owner, "max", None)
        if low is not None or high is not None:
            return low, high
    return None, None


def _number_kind(param: Any) -> str | None:
    """``"whole number"`` or ``"number"`` for an option of int or float, else None."""
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    name = str(getattr(getattr(param, "type", None), "name", ""))
    if annotation is int or name.startswith("integer"):
        return "whole number"
    if annotation is float or name.startswith("float"):
        return "number"
    return None


def _given(param: Any, args: list[str]) -> str | None:
    """The value given on the command line for the option ``param`` (its last one)."""
    value = None
    for k, arg in enumerate(args):
        for opt in param.opts:
            if arg == opt and k + 1 < len(args):
                value = args[k + 1]
            elif opt.startswith("--") and arg.startswith(f"{opt}="):
                value = arg[len(opt) + 1 :]
            elif not opt.startswith("--") and arg.startswith(opt) and len(arg) > len(opt):
                value = arg[len(opt) :]
    return value


def number_message(param: Any, args: list[str]) -> str | None:
    """The package's words for a bad value of a numeric option: the option, the value given
    and what to give (typer's are pydantic's or click's, and name no fix); None for others."""
    kind = _number_kind(param) if getattr(param, "param_type_name", "") == "option" else None
    if kind is None:
        return None
    opt = max(param.opts, key=len)
    low, high = _bounds(param)
    if low is not None and high is not None:
        rule, example = f"a {kind} from {low:,} to {high:,}", low
    elif low is not None:
        rule, example = f"a {kind} of at least {low:,}", low
    elif high is not None:
        rule, example = f"a {kind} of at most {high:,}", high
    else:
        rule, example = f"a {kind}", 1
    given = _given(param, args)
    got = f", not {given!r}" if given is not None else ""
    return f"{opt} takes {rule}{got}; give e.g. {opt} {example}"
