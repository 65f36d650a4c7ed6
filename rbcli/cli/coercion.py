"""typer's conversion of command-line values, without pydantic for the plain parameters.

typer 0.29 converts every command-line value through a pydantic TypeAdapter built per parameter
(`typer._coercion.build_runtime_param`): importing pydantic and building the adapters cost ~0.05-0.1 s
of every command, a tenth of a short `rbsim run` (docs/performance.md, "Start-up"). For a parameter
typed str, int, float, bool or Path (or Optional of one) without typer's extras (a parser, bounds,
choices), or a list of one (`rbsim validate FILE...`), `install()` converts here a value that is already
of its type, or a string that is plainly one: `int` of `-?[0-9]+`, `float` of a decimal number such as
1e-3, Path of a non-empty string (which then passes typer's own path checks, `coerce_cli_path`).
pydantic's lax mode converts those strings to the same values. Anything else (`inf`, `1_000`, `abc`, an
enum, a list of anything else, a list with one such item) goes through typer's own
conversion, which gives its result or its error message, as before. With a typer whose internals differ,
nothing is changed. tests/cli/test_coercion.py holds the cases.
"""

from __future__ import annotations

import re
import types
from pathlib import Path
from typing import Any, Union, get_args, get_origin

_INT = re.compile(r"-?[0-9]+")
_FLOAT = re.compile(r"-?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")

_installed = False
_active = False


def active() -> bool:
    """Whether plain parameters are converted here (False with a typer whose internals differ)."""
    return _active


def plain_type(annotation: Any, parameter_info: Any) -> type | None:  # noqa: ANN401 - typer's types
    """The parameter's type when it is one this module converts (see the module docstring), else None."""
    if get_origin(annotation) in (Union, types.UnionType):
        members = [a for a in get_args(annotation) if a is not type(None)]
        if len(members) != 1:
            return None
        annotation = members[0]
    if annotation not in (str, int, float, bool, Path):
        return None
    info = parameter_info
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None:
        return None
    if annotation in (int, float) and (info.min is not None or info.max is not None or info.clamp):
        return None
    if annotation is Path and info.path_type not in (None, Path):
        return None
    return annotation


def convert(kind: type, value: Any) -> tuple[bool, Any]:  # noqa: ANN401 - a command-line value
    """(True, the converted value) when `value` is plainly of type `kind` (see the module docstring)."""
    if kind is bool:
        return (True, value) if isinstance(value, bool) else (False, None)
    if type(value) is kind:
        return True, value
    if not isinstance(value, str):
        return False, None
    if kind is str:
        return True, value
    if kind is int and _INT.fullmatch(value):
        return True, int(value)
    if kind is float and _FLOAT.fullmatch(value):
        return True, float(value)
    if kind is Path and value:
        return True, Path(value)
    return False, None


def install() -> None:
    """Convert plain parameters' values without pydantic (idempotent; see the module docstring)."""
    global _installed, _active
    if _installed:
        return
    _installed = True
    try:
        from typer._coercion import RuntimeParam, build_runtime_param
        from typer._param_types import coerce_cli_path, routes_to_path
        from typer.core import _TyperParameter
    except ImportError:  # pragma: no cover - another typer: its own conversion throughout
        return
    ordinary = _TyperParameter.get_runtime_param
    if "get_runtime_param" not in vars(_TyperParameter):  # pragma: no cover
        return

    class PlainRuntimeParam(RuntimeParam):  # a frozen dataclass: fields set through __init__ below
        def __init__(self, parameter: Any, kind: type, many: bool) -> None:  # noqa: ANN401
            super().__init__(parameter_info=parameter.type_descriptor.parameter_info, annotation=kind)
            object.__setattr__(self, "kind", kind)
            object.__setattr__(self, "many", many)  # a list[kind] parameter: its values come as a sequence
            object.__setattr__(self, "parameter", parameter)

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:  # noqa: ANN401
            kind = self.kind  # type: ignore[attr-defined]
            many: bool = self.many  # type: ignore[attr-defined]
            items: list[Any] = list(value) if many and isinstance(value, (list, tuple)) else [value]
            converted = [convert(kind, item) for item in items]
            if not all(ok for ok, _ in converted) or many and not isinstance(value, (list, tuple)):
                typer_own = build_runtime_param(self.parameter.type_descriptor)  # type: ignore[attr-defined]
                return typer_own._coerce_value(value, param=param, ctx=ctx)  # its value, or its error message
            results: list[Any] = [item for _, item in converted]
            if kind is Path:
                results = [
                    coerce_cli_path(p, self.parameter_info, path_type=Path, param=param, ctx=ctx) for p in results
                ]
            return results if many else results[0]

    def get_runtime_param(self: Any) -> Any:  # noqa: ANN401
        if self._runtime_param is None:
            descriptor = self.type_descriptor
            annotation, many = descriptor.annotation, get_origin(descriptor.annotation) is list
            if many:  # list[plain]: typer hands over the values as one sequence (nargs -1 or multiple)
                members = get_args(annotation)
                annotation = members[0] if len(members) == 1 else None
            kind = plain_type(annotation, descriptor.parameter_info) if annotation is not None else None
            if descriptor.file_annotation is not None:  # typer opens files for these
                kind = None
            if kind is str and routes_to_path(str, descriptor.parameter_info):  # a str with path checks
                kind = None
            multi_value = getattr(self, "multiple", False) or getattr(self, "nargs", 1) != 1
            if kind is None or kind is bool and many or multi_value != many:
                return ordinary(self)
            self._runtime_param = PlainRuntimeParam(self, kind, many)
        return self._runtime_param

    _TyperParameter.get_runtime_param = get_runtime_param  # type: ignore[method-assign]
    _active = True
