"""Read-only arrays that stay read-only through pickling (the results of a child process).

numpy pickles an array's data but not its ``writeable`` flag: an immutable record computed in
`core.fit_process`'s child would come back with writeable arrays. `ReadOnlyArrays` restores the
flag when such a record is unpickled.
"""
from __future__ import annotations

from typing import Any

import numpy as np


def read_only(value: Any) -> Any:
    """``value`` with every ndarray in it (or in its tuples) made read-only in place."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, tuple):
        for item in value:
            read_only(item)
    return value


class ReadOnlyArrays:
    """Mixin for frozen dataclasses whose arrays are read-only: unpickled, they are again."""

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore the attributes, every array read-only."""
        for name, value in state.items():
            object.__setattr__(self, name, read_only(value))
