"""Option records: the settings of a long computation, grouped in one frozen dataclass.

A function with many settings takes ``options`` (an instance of its :class:`Options` subclass,
whose fields document each setting and its default) and, for convenience, the same settings as
keywords, which override the record's fields: ``invert_maps(obs, start, iterations=50)`` and
``invert_maps(obs, start, MapOptions(iterations=50))`` are the same call.
"""
from __future__ import annotations

import dataclasses

from hyde_bsdf.errors import UsageTypeError

__all__ = ["Options"]


@dataclasses.dataclass(frozen=True)
class Options:
    """Base of the option records."""

    @classmethod
    def of(cls, options=None, settings=None, what: str = ""):
        """``options`` (default: the defaults) with ``settings`` (field name -> value) replaced; an
        unknown name or an ``options`` of another kind is a UsageTypeError naming ``what``'s options."""
        if options is None:
            options = cls()
        if not isinstance(options, cls):
            raise UsageTypeError(f"{what}: options must be a {cls.__name__}, got {type(options).__name__}")
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(settings or {}) - set(names))
        if unknown:
            raise UsageTypeError(f"{what}() got an unexpected keyword argument {unknown[0]!r}; its options "
                                 f"({cls.__name__}) are {', '.join(names)}")
        return dataclasses.replace(options, **settings) if settings else options
