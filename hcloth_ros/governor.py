"""
The real-time governor: how many levels the node can afford to simulate.

ROS-free, so it is tested with made-up tick times (``test/test_node_units.py``).
"""


class Governor:
    """
    Caps the finest simulated level so that ticks fit in the timer period.

    After ``overrun_ticks`` ticks in a row longer than the period it drops the cap by one
    level (never below ``floor``, the LOD level); after ``headroom_ticks`` ticks in a row
    that would still fit in ``fill`` of the period with ``growth`` times the work it
    restores one. The next level has about 4x the points, but packing and publishing do
    not grow with the simulated levels: 2.5x is what a tick grew by here. Ticks right
    after start-up or a level change (first messages, restarted levels) are not judged.
    Switched off (``enabled`` False) it judges nothing and the cap stays at the top level.
    """

    def __init__(self, period, top_level, floor=0, overrun_ticks=3, headroom_ticks=60,
                 growth=2.5, fill=0.8, grace_ticks=30, enabled=True):
        if not period > 0:
            raise ValueError(f'period must be positive, got {period}')
        self.period = float(period)
        self.top_level = int(top_level)
        self.floor = int(floor)
        self.cap = self.top_level
        self.overrun_ticks = int(overrun_ticks)
        self.headroom_ticks = int(headroom_ticks)
        self.growth = float(growth)
        self.fill = float(fill)
        self.grace_ticks = int(grace_ticks)
        self._overruns = self._headroom = 0
        self._grace = self.grace_ticks
        self.enabled = bool(enabled)

    def restart_grace(self):
        """Do not judge the next ticks (the simulated levels just changed)."""
        self._grace = self.grace_ticks

    def set_enabled(self, enabled):
        """
        Switch judging on or off; either way start afresh.

        Every level, no overruns or headroom counted, a grace period: overruns counted
        before a switch-off must not shed a level at the first overrun after it.
        """
        self.enabled = bool(enabled)
        self.cap = self.top_level
        self._overruns = self._headroom = 0
        self.restart_grace()

    def judge(self, tick_seconds):
        """Account one tick; returns ``'drop'`` or ``'restore'`` if the cap changed."""
        if not self.enabled:
            return None
        if self._grace > 0:
            self._grace -= 1
            return None
        if tick_seconds > self.period:
            self._overruns, self._headroom = self._overruns + 1, 0
        elif self.growth * tick_seconds < self.fill * self.period:
            self._overruns, self._headroom = 0, self._headroom + 1
        else:
            self._overruns = self._headroom = 0
        if self._overruns >= self.overrun_ticks and self.cap > self.floor:
            self.cap -= 1
            self._overruns = 0
            return 'drop'
        if self._headroom >= self.headroom_ticks and self.cap < self.top_level:
            self.cap += 1
            self._headroom = 0
            return 'restore'
        return None


def finest_to_simulate(consumed_all, lod_level, cap, top_level):
    """
    Return the finest level to simulate.

    Every level when someone consumes the finest one (a cloud subscriber, a recording),
    else only up to the LOD marker's level; never above the governor's cap nor below the
    LOD level.
    """
    return max(min(top_level if consumed_all else lod_level, cap), lod_level)
