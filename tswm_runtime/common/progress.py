"""A progress bar over stages of estimated length, for jobs whose slow parts give no callbacks
(numba compiling a kernel on import, SymPy deriving a document).

The bar counts estimated seconds: a stage of estimate E moves the bar by E, and while it
runs a thread advances the bar with a clock (up to 95 % of E, until the stage ends), so the
bar moves during a compile too. The clock is this process's CPU time, except in a stage that
waits for another process (wall time): on a machine busy with other work the process gets
less CPU, the bar moves slower, and tqdm's remaining time (the estimated seconds left over
the bar's recent speed) grows accordingly instead of running out while the compile goes on.
"""
from __future__ import annotations

import sys
import threading
import time

TICK_S = 0.5        # how often the thread advances the bar inside a stage
INSIDE = 0.95       # the share of a stage's estimate the clock may fill before the stage ends


class Stages:
    """Named stages with estimated seconds, run in order: ``begin(name)`` ... ``end()``, then ``close()``."""

    def __init__(self, estimates: dict[str, float], *, desc: str, enabled: bool = True, file=sys.stderr,
                 clock=time.process_time, wait_clock=time.perf_counter):
        from tqdm import tqdm

        self.estimates = {name: max(float(s), 0.0) for name, s in estimates.items()}
        self._bar = tqdm(total=round(sum(self.estimates.values()), 1) or 1.0, desc=desc, unit="s", file=file,
                         disable=not enabled, bar_format="{desc}: {percentage:3.0f}%|{bar}| "
                                                         "[{elapsed}<{remaining}{postfix}]")
        self._clocks = {False: clock, True: wait_clock}   # waiting -> the clock of such a stage
        self._done = 0.0                   # estimated seconds of the stages finished
        self._lock = threading.RLock()   # the clock's thread and the stages move the bar
        self._current: tuple[str, bool, float] | None = None   # (stage, waiting, its start on its clock)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, daemon=True) if enabled else None
        if self._thread is not None:
            self._thread.start()

    def _advance_to(self, value: float) -> None:
        """Move the bar forward to ``value``, never past its total (rounded to 0.1 s: the stages' sum may
        exceed it by rounding, which tqdm would warn of and show as a negative remaining time)."""
        with self._lock:
            value = min(value, self._bar.total)
            if value > self._bar.n:
                self._bar.update(value - self._bar.n)

    @property
    def position(self) -> float:
        """Where the bar stands, in estimated seconds."""
        return float(self._bar.n)

    def tick(self) -> None:
        """Move the bar with the clock inside the stage that runs (the thread calls it)."""
        with self._lock:
            if self._current is not None:
                name, waiting, started = self._current
                inside = self._clocks[waiting]() - started
                self._advance_to(self._done + min(inside, INSIDE * self.estimates.get(name, 0.0)))

    def _tick(self) -> None:
        while not self._stop.wait(TICK_S):
            self.tick()

    def begin(self, name: str, waiting: bool = False) -> None:
        """End the stage that runs, if any, and start ``name``: the bar says its name and moves
        with the clock until the next ``begin`` or ``end``. ``waiting``: the stage waits for
        another process (the bar moves with the wall clock)."""
        with self._lock:
            self.end()
            self._bar.set_postfix_str(name, refresh=True)
            self._current = (name, waiting, self._clocks[waiting]())

    def end(self) -> None:
        """End the stage that runs: the bar moves to its end."""
        with self._lock:
            if self._current is not None:
                self._done += self.estimates.get(self._current[0], 0.0)
                self._current = None
                self._advance_to(self._done)

    def close(self) -> None:
        """End the stage that runs, stop the clock's thread, close the bar."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.end()
        self._bar.close()
