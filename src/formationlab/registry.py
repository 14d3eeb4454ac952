"""Registries: name -> class maps for laws, integrators and robot models.

A :class:`Registry` is a read-only mapping from a name (as written in scenario
files) to a class with a ``name`` class attribute, filled by its
:meth:`~Registry.register` decorator. Lookups ignore case (``"RK4"`` finds
``"rk4"``) and an unknown name raises
:class:`~formationlab.errors.UnknownNameError` (a ``ParameterError`` and a
``KeyError``) that suggests the nearest name and lists the known ones, like
scipy's ``solve_ivp(method=...)``.

:meth:`Registry.build` makes an instance from keyword parameters: a parameter
the class does not take but another class of the registry does is ignored with
an :class:`~formationlab.errors.IgnoredKeyWarning` (it has no effect, as with
``solve_ivp``'s extraneous options); a parameter no class takes is an error
with a suggestion. :func:`resolve` lets an API accept a name wherever it
accepts an instance.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Generic, TypeVar

from .errors import IgnoredKeyWarning, ParameterError, UnknownNameError
from .validation import choices

__all__ = ["Registry", "parameters_of", "resolve"]

T = TypeVar("T")
C = TypeVar("C", bound=type)


def parameters_of(cls: type) -> tuple[str, ...]:
    """The keyword parameters of a configuration class: its dataclass ``init`` fields."""
    if not dataclasses.is_dataclass(cls):
        return ()
    return tuple(f.name for f in dataclasses.fields(cls) if f.init)


class Registry(Mapping[str, type[T]], Generic[T]):
    """Classes of one kind by name; a read-only mapping (``sorted(r)``, ``r[name]``, ``name in r``).

    Parameters
    ----------
    kind : str
        What the entries are, for messages: ``"law"``, ``"integrator"``, ``"robot model"``.

    Examples
    --------
    >>> from formationlab.integrators import INTEGRATORS
    >>> INTEGRATORS["RK4"].name
    'rk4'
    >>> "filippov" in INTEGRATORS, INTEGRATORS.names()[:2]
    (True, ('euler', 'filippov'))
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._classes: dict[str, type[T]] = {}

    # ------------------------------------------------------------------ filling

    def register(self, cls: C) -> C:
        """Class decorator: make ``cls`` available by its ``name`` class attribute."""
        name = getattr(cls, "name", "")
        if not isinstance(name, str) or not name:
            raise TypeError(f"{cls.__name__} has no name; set the class attribute name")
        other = self._lower().get(name.lower())
        if other is not None and other != name:
            raise TypeError(f"{self.kind} {name!r} differs from {other!r} only in case")
        self._classes[name] = cls
        return cls

    def __delitem__(self, name: str) -> None:
        """Remove an entry (for tests and plug-ins that unload)."""
        del self._classes[self.canonical(name)]

    # ------------------------------------------------------------------ lookup

    def _lower(self) -> dict[str, str]:
        return {k.lower(): k for k in self._classes}

    def names(self) -> tuple[str, ...]:
        """The registered names, sorted."""
        return tuple(sorted(self._classes))

    def canonical(self, name: str) -> str:
        """The registered spelling of ``name`` (any case); else :class:`UnknownNameError`."""
        if name in self._classes:
            return name
        found = self._lower().get(str(name).lower())
        if found is None:
            raise UnknownNameError(
                f"unknown {self.kind} {name!r}{choices(str(name), self.names())}"
            )
        return found

    def __getitem__(self, name: str) -> type[T]:
        return self._classes[self.canonical(name)]

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name.lower() in self._lower()

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._classes)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self.names())})"

    def owners(self, key: str) -> tuple[str, ...]:
        """Names of the entries that take the parameter ``key`` (or have it in ``initial_keys``)."""
        return tuple(
            n
            for n in self.names()
            if key in parameters_of(self._classes[n])
            or key in getattr(self._classes[n], "initial_keys", ())
        )

    # ------------------------------------------------------------------ building

    def split(self, name: str, params: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
        """``(taken, ignored)``: the parameters entry ``name`` takes, and those of other entries.

        Raises
        ------
        UnknownNameError
            ``name`` is not registered.
        ParameterError
            A parameter no entry takes (``key`` is set; the message suggests the nearest).
        """
        cls = self[name]
        own = parameters_of(cls)
        taken: dict[str, Any] = {}
        ignored: dict[str, Any] = {}
        for key, value in params.items():
            if key in own:
                taken[key] = value
            elif self.owners(key):
                ignored[key] = value
            else:
                raise ParameterError(
                    f"the {self.kind} {self.canonical(name)!r} takes no parameter {key!r}"
                    f"{choices(key, own, 'It takes')}",
                    key=key,
                )
        return taken, ignored

    def ignored_message(self, name: str, ignored: Iterable[str]) -> str:
        """One line: the ``ignored`` parameters have no effect on entry ``name``; whose they are."""
        keys = list(ignored)
        owners = ", ".join(repr(o) for o in sorted({o for k in keys for o in self.owners(k)}))
        one = len(keys) == 1
        return (
            f"{', '.join(keys)} {'has' if one else 'have'} no effect: "
            f"{'it is not a parameter' if one else 'they are not parameters'} of the "
            f"{self.kind} {self.canonical(name)!r} ({'it belongs' if one else 'they belong'} "
            f"to {owners}); remove {'it' if one else 'them'} or change the {self.kind}"
        )

    def build(self, name: str, /, **params: Any) -> T:
        """An instance of entry ``name`` with ``params``.

        Parameters of other entries are ignored with an :class:`IgnoredKeyWarning`;
        unknown ones raise :class:`ParameterError`.
        """
        taken, ignored = self.split(name, params)
        if ignored:
            warnings.warn(self.ignored_message(name, ignored), IgnoredKeyWarning, stacklevel=3)
        return self[name](**taken)


def resolve(registry: Registry[T], obj: T | str, /, **params: Any) -> T:
    """``obj`` itself, or the entry of ``registry`` named ``obj`` built with ``params``.

    Lets an API take ``"rk4"`` wherever it takes ``RK4(...)``.
    """
    if isinstance(obj, str):
        return registry.build(obj, **params)
    if params:
        raise ParameterError(
            f"parameters {', '.join(params)} are for a {registry.kind} given by name; "
            f"this one is already built: {obj!r}"
        )
    return obj
