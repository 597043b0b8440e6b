"""One line when numba compiles one of undertow's kernels, so that the pause that follows (up to
a minute or two on the first use after an install or an update) reads as compiling, not as a
hang. The kernels are cached on disk (``cache=True``), so later runs load them instead.

numba triggers its ``numba:compile`` event only when it compiles a signature, not when it
loads one from its cache (``Dispatcher.compile`` in numba/core/dispatcher.py; the event API in
numba/core/event.py).
"""

from __future__ import annotations

import threading

from numba.core import event

NOTICE = (
    "compiling undertow's numba kernels for this machine (the first use after an install or "
    "an update can take a minute or two; they are cached for later runs)"
)


class CompileNotice(event.Listener):
    """Calls ``say(NOTICE)`` at the first compilation of a function of the ``undertow`` package
    it is told of, once."""

    def __init__(self, say) -> None:
        self.say = say
        self.said = False
        self._lock = threading.Lock()

    def on_start(self, ev) -> None:
        dispatcher = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
        if module.split(".")[0] != "undertow":
            return
        with self._lock:
            if self.said:
                return
            self.said = True
        self.say(NOTICE)

    def on_end(self, ev) -> None:
        pass


def install(say) -> CompileNotice:
    """Register a :class:`CompileNotice` for the rest of the process; returns it."""
    listener = CompileNotice(say)
    event.register("numba:compile", listener)
    return listener
