"""Step results built fast, their rarely read parts on first read.

A frozen dataclass's ``__init__`` sets each field through ``object.__setattr__`` (~10 us
for a ``StepResult``); ``build`` fills the instance's ``__dict__`` instead (well under
1 us), the same object. ``build_deferred`` gives an instance whose fields ``names`` a
callable computes only when one of them is first read: the routes that step the
simulation (``core.fast``, the facade's measures of the barrier and soft-finger routes)
leave what observers rarely read (energies, wrenches, the fingers' result, ...) to
then. A deferred instance compares, prints, pickles and copies as its dataclass
(pickles and copies become plain instances).
"""
from __future__ import annotations

import dataclasses
import threading
from typing import Callable

#: one fill at a time: a node's physics thread and its publisher read the same results
_FILLING = threading.RLock()


def _frozen_builder(cls):
    """A fast constructor for the (frozen) dataclass ``cls`` (see the module docstring).
    Fields left out take their defaults. Falls back to ``cls(**fields)`` (which raises)
    for missing or unknown fields, and for a class with a ``__post_init__``, slots or
    default factories."""
    fields = dataclasses.fields(cls)
    size = len(fields)
    defaults = {f.name: f.default for f in fields if f.default is not dataclasses.MISSING}
    plain = (not hasattr(cls, '__post_init__') and not hasattr(cls, '__slots__')
             and all(f.default_factory is dataclasses.MISSING for f in fields))
    new = object.__new__
    set_attribute = object.__setattr__

    def build_one(values: dict):
        """``values`` (a fresh dict the caller gives away) becomes the instance dict."""
        if plain:
            obj = new(cls)
            if len(values) == size:  # every field given (the fast paths do)
                set_attribute(obj, '__dict__', values)
                return obj
            state = obj.__dict__
            state.update(defaults)
            state.update(values)
            if len(state) == size:  # no field missing, none unknown
                return obj
        return cls(**values)
    return build_one


#: the fast constructor of each dataclass built so far
_BUILDERS: dict = {}


def build(cls, fields: dict):
    """The ``cls`` (a frozen dataclass) instance of ``fields`` (a fresh dict given away)."""
    builder = _BUILDERS.get(cls)
    if builder is None:
        builder = _BUILDERS[cls] = _frozen_builder(cls)
    return builder(fields)


class _Deferred:
    """A field of a ``_deferred_class`` instance, filled on first read: the instance's
    ``_fill()`` gives every deferred field at once; they then live in its ``__dict__``
    (which this non-data descriptor yields to). Threads may read the same instance: the
    first fills it, the others wait and read what it filled."""

    def __init__(self, name: str):
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        state = obj.__dict__
        with _FILLING:
            fill = state.get('_fill')
            if fill is not None:
                state.update(fill())
                del state['_fill']
        return state[self.name]


def _plain(cls, fields: dict):
    """The ``cls`` instance of ``fields`` (what a deferred instance pickles and copies to)."""
    return build(cls, fields)


def _deferred_class(cls, names: tuple[str, ...]):
    """A subclass of the frozen dataclass ``cls`` whose fields ``names`` are built only
    when read. It compares, prints, pickles and copies as ``cls``."""
    fields = [f.name for f in dataclasses.fields(cls)]

    def as_plain(self):
        return _plain, (cls, {name: getattr(self, name) for name in fields})

    def __eq__(self, other):
        if not isinstance(other, cls):
            return NotImplemented
        return (tuple(getattr(self, name) for name in fields)
                == tuple(getattr(other, name) for name in fields))

    namespace = {name: _Deferred(name) for name in names}
    namespace.update(__reduce__=as_plain, __eq__=__eq__, __hash__=cls.__hash__,
                     __qualname__=cls.__qualname__, __module__=cls.__module__,
                     __doc__=cls.__doc__)
    return type(cls.__name__, (cls,), namespace)


#: the deferred subclass of each (dataclass, deferred field names) built so far
_DEFERRED: dict = {}


def build_deferred(cls, fields: dict, names: tuple[str, ...], fill: Callable[[], dict]):
    """A ``cls`` instance of ``fields`` (a fresh dict given away, without ``names``) whose
    fields ``names`` ``fill()`` gives, as a dict holding each of them, when one is first
    read."""
    key = (cls, names)
    subclass = _DEFERRED.get(key)
    if subclass is None:
        subclass = _DEFERRED[key] = _deferred_class(cls, names)
    obj = object.__new__(subclass)
    fields['_fill'] = fill
    object.__setattr__(obj, '__dict__', fields)
    return obj
