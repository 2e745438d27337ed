"""
The node's ``/diagnostics`` message.

What a ``diagnostic_aggregator`` or ``rqt_robot_monitor`` shows of the simulation (no
node, no graph: tested with plain pytest).
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

SLOW = 0.9      # below this share of the asked real-time factor the status warns


def node_status(name, stamp, recent, real_time_factor, target_factor, paused, levels,
                level_count, governor_cap, refused, sim_time):
    """
    Return a ``DiagnosticArray`` with one status for the simulation node ``name``.

    ``recent``: :meth:`TickStats.recent` over the last period (ms); ``real_time_factor``:
    simulated over wall seconds over that period (None when a reset sent the time back in
    it); ``target_factor``: the one asked for (0: as fast as possible); ``governor_cap``:
    the finest level the governor allows, None when it is off; ``refused``: why the last
    step was refused, None if it went through.
    The level is ERROR after a refused step, WARN while running slower than asked or with
    levels shed by the governor, else OK (paused included).
    """
    level, message = DiagnosticStatus.OK, 'paused' if paused else 'running'
    if refused:
        level, message = DiagnosticStatus.ERROR, f'last step refused: {refused}'
    elif governor_cap is not None and governor_cap < level_count - 1:
        level, message = DiagnosticStatus.WARN, (
            f'governor sheds levels: simulating up to level {governor_cap}')
    elif (not paused and target_factor > 0 and real_time_factor is not None
          and real_time_factor < SLOW * target_factor):
        level, message = DiagnosticStatus.WARN, (
            f'slower than asked: real-time factor {real_time_factor:.2f} of {target_factor:g}')
    values = {'paused': str(paused).lower(), 'sim_time_s': f'{sim_time:.6f}',
              'real_time_factor': (f'{real_time_factor:.3f}' if real_time_factor is not None
                                   else 'n/a'),
              'real_time_factor_target': f'{target_factor:g}',
              'levels_simulated': str(levels), 'level_count': str(level_count),
              'governor_cap': 'off' if governor_cap is None else str(governor_cap)}
    for phase, stats in recent.items():
        for pct, ms in stats.items():
            values[f'{phase}_{pct}_ms'] = f'{ms:.3f}'
    status = DiagnosticStatus(level=level, name=f'{name.lstrip("/")}: cloth simulation',
                              message=message, hardware_id=name,
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
    array = DiagnosticArray(status=[status])
    array.header.stamp = stamp
    return array
