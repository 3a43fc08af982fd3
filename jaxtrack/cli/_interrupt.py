"""Ctrl-C for the command line: a KeyboardInterrupt that is neither lost nor raised where it crashes.

Python acts on SIGINT by raising KeyboardInterrupt in the main thread at its next bytecode
boundary, wherever that is. Some places are bad ones:

* a *garbage-collector callback*: JAX registers ``_xla_gc_callback`` in ``gc.callbacks`` when it
  is imported, and a KeyboardInterrupt raised there is reported as "Exception ignored in: …" and
  discarded (so is one raised in a ``__del__`` method or a weakref callback). During the imports
  of a study the collector runs so often that most Ctrl-Cs between 0.7 and 3 s after the start
  of ``jaxtrack reproduce multitarget`` were lost so, and the study ran on to its end;
* a C extension's import: raised while jaxlib's modules are being created (Python code that
  their initialisation calls back), it has ended the process with SIGSEGV instead of status 130;
* a long call into C++ (an XLA compilation, an extension's initialisation): Python's handler
  runs only once it returns.

:func:`install` guards against all three, for the command line proper (never for the library):

1. a SIGINT handler that records the interrupt and raises KeyboardInterrupt, unless the main
   thread is inside a collector callback or a C extension's import (its frames say so): then it
   only asks the watchdog (2) to deliver the interrupt again ~50 ms later, until it lands
   elsewhere. It also turns the automatic collector off: the process is ending, and the
   collector's callbacks are the most frequent bad place;
2. ``signal.set_wakeup_fd``: the C-level signal handler writes the signal's number to a socket at
   once, whatever the main thread is doing, and a daemon *watchdog* thread reads it. The watchdog
   delivers deferred interrupts again (``_thread.interrupt_main``);
3. a ``sys.unraisablehook`` that recognises our KeyboardInterrupt being discarded anyway (no
   traceback printed) and has the watchdog deliver it again;
4. the watchdog's deadline: a process still running ``grace_s`` seconds after the first Ctrl-C
   (the interrupt swallowed somewhere else, or the main thread inside a long C++ call) prints
   ``jaxtrack: interrupted`` and ends with status 130 (``os._exit``); a second Ctrl-C does so at
   once.

A delivered KeyboardInterrupt unwinds the command normally: temporary files are deleted,
``jaxtrack.cli.main`` prints ``jaxtrack: interrupted`` and exits with status 130.
"""

from __future__ import annotations

import _thread
import contextlib
import gc
import importlib.machinery
import os
import signal
import socket
import sys
import threading
import time

MESSAGE = "jaxtrack: interrupted"
STATUS = 130
GRACE_S = 3.0
"""Seconds after the first Ctrl-C before the watchdog ends a process that is still running."""
REDELIVER_S = 0.05
"""Pause before a deferred or discarded interrupt is delivered again."""
_WAKE = 0  # byte sent to the watchdog by the main thread: an interrupt to deliver again (0 is no signal)
# The frames of a C extension's creation and execution (its PyInit, and what that calls back).
_EXTENSION_CODES = frozenset({importlib.machinery.ExtensionFileLoader.create_module.__code__,
                              importlib.machinery.ExtensionFileLoader.exec_module.__code__})


def _bad_place(frame) -> bool:
    """True when a KeyboardInterrupt raised in ``frame`` would be discarded or unsafe: a frame on
    the stack is a garbage-collector callback's or a C extension's creation or execution."""
    codes = set(_EXTENSION_CODES)
    for cb in gc.callbacks:
        code = getattr(getattr(cb, "__func__", cb), "__code__", None)
        if code is not None:
            codes.add(code)
    while frame is not None:
        code = frame.f_code
        if code in codes:
            return True
        frame = frame.f_back
    return False


class Guard:
    """The installed guard (see the module docstring); :meth:`uninstall` restores what it replaced."""

    def __init__(self, grace_s: float, exit_fn, message: str, status: int):
        self.grace_s = grace_s
        self.exit_fn = exit_fn
        self.message = message
        self.status = status
        self.requested = False  # set by the first Ctrl-C, in the main thread
        self.deferred = 0  # times the main thread put the interrupt off (bad place, or discarded)
        self.delivered = 0  # times the watchdog delivered it again
        self._pending = False
        self._gc_was_enabled = gc.isenabled()
        self._reader, self._writer = socket.socketpair()
        self._writer.setblocking(False)
        self._previous_handler = signal.signal(signal.SIGINT, self._handler)
        self._previous_fd = signal.set_wakeup_fd(self._writer.fileno(), warn_on_full_buffer=False)
        self._previous_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        self._thread = threading.Thread(target=self._watch, name="jaxtrack-ctrl-c", daemon=True)
        self._thread.start()

    # -- main thread ----------------------------------------------------------------------------
    def _handler(self, signum, frame):
        self.requested = True
        gc.disable()
        if _bad_place(frame):
            self._defer()
            return
        raise KeyboardInterrupt

    def _defer(self) -> None:
        self.deferred += 1
        self._pending = True
        try:
            self._writer.send(bytes([_WAKE]))
        except OSError:  # full (the watchdog is behind: it delivers anyway) or closed
            pass

    def _unraisable(self, unraisable):
        if self.requested and unraisable.exc_type is KeyboardInterrupt:
            self._defer()
            return
        self._previous_hook(unraisable)

    def uninstall(self) -> None:
        """Restore the SIGINT handler, wakeup fd, unraisable hook and collector; stop the watchdog."""
        signal.set_wakeup_fd(self._previous_fd)
        signal.signal(signal.SIGINT, self._previous_handler)
        if sys.unraisablehook == self._unraisable:
            sys.unraisablehook = self._previous_hook
        if self._gc_was_enabled:
            gc.enable()
        self._writer.close()  # the watchdog's recv returns b"": it ends
        self._thread.join(timeout=5)
        self._reader.close()

    # -- watchdog thread ------------------------------------------------------------------------
    def _watch(self) -> None:
        interrupts = 0  # Ctrl-Cs from outside, not our own deliveries
        own = 0  # SIGINT bytes still to come from our own interrupt_main calls
        deadline = None
        next_delivery = None
        while True:
            wake_at = [t for t in (deadline, next_delivery) if t is not None]
            self._reader.settimeout(max(0.0, min(wake_at) - time.monotonic()) if wake_at else None)
            try:
                data = self._reader.recv(256)
            except TimeoutError:
                data = None
            except OSError:
                return
            if data == b"":  # uninstalled
                return
            now = time.monotonic()
            for byte in data or b"":
                if byte == signal.SIGINT:
                    if own:
                        own -= 1
                        continue
                    interrupts += 1
                    if interrupts >= 2:
                        self._end()
                        return
                    if deadline is None:
                        deadline = now + self.grace_s
                elif byte == _WAKE and next_delivery is None:
                    next_delivery = now + REDELIVER_S
            if deadline is not None and now >= deadline:
                self._end()
                return
            if next_delivery is not None and now >= next_delivery:
                next_delivery = None
                if self._pending:
                    self._pending = False
                    self.delivered += 1
                    own += 1
                    _thread.interrupt_main(signal.SIGINT)

    def _end(self) -> None:
        # Flush stdout (the tables printed so far) unless that would block, then end the process.
        flusher = threading.Thread(target=_flush_stdout, daemon=True)
        flusher.start()
        flusher.join(timeout=0.5)
        with contextlib.suppress(OSError):
            os.write(2, f"\n{self.message}\n".encode())
        self.exit_fn(self.status)


def _flush_stdout() -> None:
    with contextlib.suppress(Exception):  # a closed or broken stdout: nothing to save
        sys.stdout.flush()


def install(grace_s: float = GRACE_S, exit_fn=os._exit, message: str = MESSAGE,
            status: int = STATUS) -> Guard | None:
    """Install the Ctrl-C guard (main thread only); None when SIGINT is ignored or not ours to take.

    A process started with SIGINT ignored (``nohup``, ``cmd &`` in a non-interactive shell) keeps
    it ignored, as Python itself does. ``exit_fn(status)`` ends the process (``os._exit`` on the
    command line; a test passes its own).
    """
    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return None
    return Guard(grace_s, exit_fn, message, status)
