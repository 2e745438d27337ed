"""
Recovery from a refused step: the same time span again in smaller steps.

A step is refused when it would write a non-finite state or stretch a spring beyond
``blowup_strain`` (:class:`~hcloth_ros.core.solvers.Solver`), or, with the solver's
``retry_strain`` set, when self-contact found pairs and it stretches one beyond that
from a start where none was (``stretched``); the state keeps its last good value.
Stiffness the step is too long for can do that at the node's step and not at half or a
quarter of it, and so can layers of the cloth meeting fast: self-contact pushes them
apart a pair at a time, and the shorter the step the less each push stretches the
springs round it. Grasps and moving bodies move evenly over the smaller steps, at the
speed the step asked of them (:meth:`Control.follow
<hcloth_ros.core.control.Control.follow>`).
"""

from contextlib import contextmanager

from hcloth_ros.core.solvers import merged

SPLITS = (2, 4, 8)


@contextmanager
def _stretch_allowed(solver, allowed):
    """Within it, ``solver`` refuses no step as ``stretched`` (if ``allowed``)."""
    kept = solver.retry_strain
    if allowed:
        solver.retry_strain = None
    try:
        yield
    finally:
        solver.retry_strain = kept


def retry_warning(solver):
    """
    Return why the solver's retries would redo steps its strain limit accepts, or None.

    ``retry_strain`` not above ``strain_limit``, with self-contact on: strain limiting
    leaves springs up to the limit, so a step in which self-contact found pairs and that
    stretches a spring of a cloth within ``retry_strain`` past it, but not past the limit,
    is refused and taken again in up to 2 + 4 + 8 smaller steps for a stretch the limit
    allows.
    """
    retry, limit = solver.retry_strain, solver.strain_limit
    if solver.self_contact is None or retry is None or limit is None or retry > limit:
        return None
    return (f'solver.retry_strain {retry:g} is not above solver.strain_limit {limit:g}: '
            f'a self-contact step that stretches springs past {retry:g} but within the '
            'limit will be taken again in up to 14 smaller steps; set it above the limit '
            '(the default 0.5) or to 0 to switch retries off')


def step_with_retries(solver, state, control, dt, splits=SPLITS):
    """
    Advance ``state`` by ``dt``; if refused, again from the same start in n steps of dt/n.

    n takes the values of ``splits`` in turn. Returns ``(report, n)``: the last report
    (:func:`~hcloth_ros.core.solvers.merged` over the n steps that went through: their
    largest strain in ``peak_strain``; ``seconds`` the time of every try) and the steps it
    took (1: the first try went through; 0: every try was refused, and the
    state, grasps and moving bodies are where they were; the report is the first refusal,
    or the last one if the first was only ``stretched``). A report after retries holds why
    the first try was refused in ``extra['refused']`` (its reason without "step refused,
    last good state kept"). A try whose smaller steps went through in part is undone whole:
    state, grasps, bodies and the solver's memory (``solver.checkpoint``). Step i of n
    asks grasps and bodies to be i / n of their way to the poses the step asked
    (``control.follow``). The last n takes its steps however far they stretch the springs
    (below ``blowup_strain``): a strain that smaller steps do not bring under
    ``retry_strain`` is kept rather than the cloth stopped, unless they stretch them
    further than the whole step did: then the whole step is taken after all (n = 1, its
    report's ``extra['refused']`` and ``extra['smaller_strain']`` say so; :func:`_whole_step`).
    """
    report = solver.step(state, control, dt)
    if report.ok:
        return report, 1
    refused, start, plan, kept = report, state.copy(), control.plan(), solver.checkpoint()
    spent = report.seconds
    why = refused.reason.split(': step refused')[0]
    for n in splits:
        with _stretch_allowed(solver, n == splits[-1]):
            taken = []
            for i in range(1, n + 1):
                control.follow(plan, i / n)
                report = solver.step(state, control, dt / n)
                spent += report.seconds
                if not report.ok:
                    _undo(solver, state, control, start, plan, kept)
                    break
                taken.append(report)
            else:
                report = merged(taken, spent)
                if refused.stretched and report.peak_strain > refused.max_strain:
                    return _whole_step(solver, state, control, dt, (start, plan, kept),
                                       report, why), 1
                report.extra['refused'] = why
                return report, n
    # a stretched first try was not what stopped the last, which ran without that check
    report = report if refused.stretched else refused
    report.seconds = spent
    return report, 0


def retried(report, taken):
    """
    Whether :func:`step_with_retries`, returning ``(report, taken)``, had to retry the step.

    Smaller steps went through (``taken`` > 1), the whole step was taken after all (1,
    with ``extra['refused']``), or none went through (0).
    """
    return taken != 1 or 'refused' in report.extra


def _undo(solver, state, control, start, plan, kept):
    """Put state, grasps, bodies and the solver's memory back where the step started."""
    state.assign(start)
    control.rewind(plan)
    solver.restore(kept)


def _whole_step(solver, state, control, dt, begun, smaller, why):
    """
    Take the step whole after all, its stretch allowed; return its report.

    For a step refused only as stretched whose last resort, the smallest steps, stretched
    the springs further than the whole step had (``smaller``: their merged report): the
    fold demo's scene solved on 65 x 65 (seed 6), a gripper lowering its held corner onto
    the bottom layer on the ground, stretched them to 0.60 in one step with 3 edges
    through triangles, undone 1 s later, and to 1.36 in 8 steps with 16 that stayed. The
    report's ``extra``: ``refused`` (why the first try was), ``smaller_strain`` (the
    smallest steps' largest strain), and its ``seconds`` every try's.
    """
    _undo(solver, state, control, *begun)
    with _stretch_allowed(solver, True):
        report = solver.step(state, control, dt)
    report.seconds += smaller.seconds
    report.extra['refused'] = why
    report.extra['smaller_strain'] = smaller.peak_strain
    return report
