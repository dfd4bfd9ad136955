"""Shared check that a native call releases the GIL: a Python thread keeps counting while it runs."""

from __future__ import annotations

import threading
from collections.abc import Callable


def python_ticks_during(call: Callable[[], object]) -> int:
    """How many loop iterations a Python thread managed while `call` ran."""
    ticks = 0
    done = threading.Event()

    def count() -> None:
        nonlocal ticks
        while not done.is_set():
            ticks += 1

    counter = threading.Thread(target=count)
    counter.start()
    before = ticks
    call()
    during = ticks - before
    done.set()
    counter.join()
    return during
