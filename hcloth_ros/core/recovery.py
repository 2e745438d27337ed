"""
Recovery from a refused step: the same time span again in smaller steps.

A step is refused when it would write a non-finite state or stretch a spring beyond
``blowup_strain`` (:class:`~hcloth_ros.core.solvers.Solver`); the state keeps its last good
value. Stiffness the step is too long for can do that at the node's step and not at half or
a quarter of it. A grasp or a body that jumps is not helped: held points and bodies reach
their poses in the first of the smaller steps (nothing is interpolated).
"""

SPLITS = (2, 4, 8)


def step_with_retries(solver, state, control, dt, splits=SPLITS):
    """
    Advance ``state`` by ``dt``; if refused, again from the same start in n steps of dt/n.

    n takes the values of ``splits`` in turn. Returns ``(report, n)``: the last report and
    the steps it took (1: the first try went through; 0: every try was refused, and state
    and moving bodies are where they were). Held points reach their targets and moving
    bodies their poses in the first of the n steps, then stay.
    """
    report = solver.step(state, control, dt)
    if report.ok:
        return report, 1
    refused = report
    for n in splits:
        start, starts = state.copy(), control.bodies.starts()
        for _ in range(n):
            report = solver.step(state, control, dt / n)
            if not report.ok:
                state.assign(start)
                control.bodies.restore(starts)
                break
        else:
            return report, n
    return refused, 0
