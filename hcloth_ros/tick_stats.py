"""Per-tick phase times of the node, summarised when it stops."""

from dataclasses import dataclass, field
import time

import numpy as np


# send: the publishing thread's time for the tick before, outside the tick (0 without it)
PHASES = ('step', 'pack', 'publish', 'send', 'record', 'tick')


@dataclass
class TickStats:
    """
    Phase times (s) of every tick.

    Percentiles over the last ``window`` ticks (10 minutes at 60 Hz), the real-time
    factor over the whole run. Each series is a float64 ring allocated at its first tick:
    deques of Python floats grew the node by about 2 MB a minute until they were full
    (the soak benchmark), a ring takes its memory once.
    """

    window: int = 36000
    samples: dict = field(default_factory=dict)
    count: int = 0
    wall_start: float = None

    def add(self, **values):
        """Record one tick: the phase times, ``levels`` simulated and ``sim_time``."""
        if self.wall_start is None:
            self.wall_start = time.monotonic() - values['tick']
        slot = self.count % self.window
        for name, value in values.items():
            if name not in self.samples:
                self.samples[name] = np.zeros(self.window)
            self.samples[name][slot] = value
        self.count += 1

    def series(self, name, ticks=None):
        """Return the last ``ticks`` values of one series, oldest first (all: its window)."""
        held = min(self.count, self.window)
        ticks = held if ticks is None else min(ticks, held)
        end = self.count % self.window
        ring = self.samples[name]
        if ticks <= end:
            return ring[end - ticks:end]
        return np.concatenate([ring[self.window - (ticks - end):], ring[:end]])

    def summary(self):
        """
        Return p50/p99 in ms of each phase, ticks, real-time factor, levels simulated.

        ``top_levels`` holds the same percentiles over the ticks that simulated the most
        levels of the window only, and their count: the node's cost at its full
        resolution, without the ticks before a subscriber wanted the finest level or
        after the governor shed levels.
        """
        out = {'ticks': self.count}
        levels = self.series('levels')
        top = levels == levels.max()
        out['top_levels'] = {'ticks': int(top.sum())}
        for name in PHASES:
            ms = self.series(name) * 1e3
            out[name] = _percentiles(ms)
            out['top_levels'][name] = _percentiles(ms[top])
        wall = time.monotonic() - self.wall_start
        out['real_time_factor'] = self.series('sim_time', 1)[0] / wall if wall > 0 else 0.0
        out['levels_min'] = int(levels.min())
        out['levels_max'] = int(levels.max())
        return out

    def recent(self, ticks):
        """Return p50/p99 in ms of each phase over the last ``ticks`` ticks ({} if none)."""
        if ticks <= 0 or not self.count:
            return {}
        return {name: _percentiles(self.series(name, ticks) * 1e3) for name in PHASES}


def _percentiles(ms):
    return {'p50': float(np.percentile(ms, 50)), 'p99': float(np.percentile(ms, 99))}
