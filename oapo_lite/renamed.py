"""Names that changed: a config or function refuses a retired keyword with the one line that
names its new one (a plain TypeError would say only that the keyword is unknown)."""
from __future__ import annotations

import functools


def refuse(renames: dict[str, str]):
    """Decorate a class (its constructor) or a function so that each retired keyword of
    ``renames`` (old -> new) raises a TypeError naming the new one."""
    def wrap(obj):
        call = obj.__init__ if isinstance(obj, type) else obj
        name = obj.__name__

        @functools.wraps(call)
        def checked(*args, **kw):
            for old in renames.keys() & kw.keys():
                raise TypeError(f"{name}'s keyword {old}= was renamed {renames[old]}=")
            return call(*args, **kw)

        if isinstance(obj, type):
            obj.__init__ = checked
            return obj
        return checked
    return wrap
