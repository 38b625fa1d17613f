"""Registries: the explicit place where lanro keeps what may be extended (tasks, reported figures), and live
views of them.

A registry holds named entries in the order they were registered; a view derived from one (the tasks'
names, the columns of ``metrics.csv``) is computed again each time it is read, so an entry registered later
(a test's own task or figure) reaches every reader without any copy to update, and leaves none once it is
unregistered.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TypeVar, overload

T = TypeVar("T")


class Live(Sequence[T]):
    """A tuple computed afresh from ``compute`` whenever it is read; equal to any sequence of the same items
    (a tuple, a list), as the tuple it stands for would be."""

    def __init__(self, compute: Callable[[], tuple[T, ...]]) -> None:
        self._compute = compute

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[T, ...]: ...

    def __getitem__(self, index: int | slice) -> T | tuple[T, ...]:
        return self._compute()[index]

    def __len__(self) -> int:
        return len(self._compute())

    def __iter__(self) -> Iterator[T]:
        return iter(self._compute())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Sequence) and not isinstance(other, str):
            return self._compute() == tuple(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(self._compute())


class Registry(Sequence[T]):
    """The entries of one kind (``what``), in registration order, each under the name ``name_of`` gives it."""

    def __init__(self, what: str, name_of: Callable[[T], str]) -> None:
        self.what = what
        self._name_of = name_of
        self._entries: dict[str, T] = {}
        self.names: Live[str] = Live(lambda: tuple(self._entries))
        """The entries' names, in order."""
        self.by_name: Mapping[str, T] = _ByName[T](self._entries)
        """The entries by name."""

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[T, ...]: ...

    def __getitem__(self, index: int | slice) -> T | tuple[T, ...]:
        return tuple(self._entries.values())[index]

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[T]:
        return iter(tuple(self._entries.values()))

    def named(self, name: str) -> T:
        """The entry ``name``, or a ``ValueError`` that lists the names known."""
        if name not in self._entries:
            raise ValueError(f"{self.what} must be one of {list(self._entries)}, got {name!r}")
        return self._entries[name]

    def register(self, entry: T) -> T:
        """Add ``entry`` after the others; a name already taken is refused."""
        name = self._name_of(entry)
        if name in self._entries:
            raise ValueError(f"a {self.what} named {name!r} is registered already")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove the entry ``name``; the others keep their order."""
        self.named(name)
        del self._entries[name]

    @contextmanager
    def registered(self, entry: T) -> Iterator[T]:
        """``entry`` registered for the ``with`` block only."""
        self.register(entry)
        try:
            yield entry
        finally:
            self.unregister(self._name_of(entry))


class _ByName(Mapping[str, T]):
    """A registry's entries by name, read through as they change."""

    def __init__(self, entries: dict[str, T]) -> None:
        self._entries = entries

    def __getitem__(self, name: str) -> T:
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._entries))

    def __len__(self) -> int:
        return len(self._entries)
