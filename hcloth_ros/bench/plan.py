"""
What a benchmark run covers: the methods, their settings and the three presets.

``full`` is what the README's charts come from; ``quick`` finishes in a few minutes on 2
cores; ``tiny`` is the seconds-long smoke run of the test suite.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Method:
    """One solver configuration: a line on the charts."""

    label: str
    solver: str
    options: tuple = ()         # (name, value) pairs for make_solver
    levels: int = 1
    max_n: int = 10 ** 6        # skip larger meshes (the implicit solver's cost)
    dts: tuple = None           # None: the plan's dts

    @property
    def kwargs(self):
        return dict(self.options)


@dataclass(frozen=True)
class Plan:
    name: str
    sizes: tuple                # finest points a side
    duration: float             # simulated seconds of each accuracy run
    dts: tuple                  # time steps of the approximate and implicit methods
    level_counts: tuple         # hierarchical variants (those that fit a size)
    implicit_tolerances: tuple
    implicit_max_n: int
    scenarios: tuple = ('swing', 'free_fall', 'grasp')
    stability_n: int = 17
    stability_duration: float = 1.0
    stiffnesses: tuple = (1e1, 1e2, 1e3, 1e4, 1e5)
    stability_dts: tuple = tuple(1 / (30 * 2 ** i) for i in range(11))    # to 1/30720 s
    paper_levels: int = 4       # Fig. 3/5/6 cloth: 9 x 9 level 0 and this many levels
    paper_seconds: float = 2.0
    fig4: bool = True           # time the paper's 8192-point cloth
    equilibrium_sizes: tuple = (17, 33)     # the hung cloth's rest shape (L-BFGS: minutes at 65)


FULL = Plan('full', sizes=(17, 33, 65), duration=2.0,
            dts=(1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480),
            level_counts=(2, 3, 4), implicit_tolerances=(1e-2, 1e-4), implicit_max_n=33)
QUICK = Plan('quick', sizes=(17,), duration=1.5, dts=(1 / 30, 1 / 60, 1 / 120, 1 / 240),
             level_counts=(2, 3), implicit_tolerances=(1e-3,), implicit_max_n=17,
             stiffnesses=(1e1, 1e3, 1e5), stability_n=9,
             stability_dts=tuple(1 / (30 * 2 ** i) for i in range(0, 9, 2)),
             paper_levels=3, paper_seconds=1.0, equilibrium_sizes=(17,))
TINY = Plan('tiny', sizes=(9,), duration=0.4, dts=(1 / 30, 1 / 60), level_counts=(2,),
            implicit_tolerances=(1e-2,), implicit_max_n=9, scenarios=('swing', 'free_fall'),
            stability_n=5, stability_duration=0.2, stiffnesses=(1e2, 1e4),
            stability_dts=(1 / 30, 1 / 480), paper_levels=2, paper_seconds=0.2, fig4=False,
            equilibrium_sizes=(9,))
PLANS = {p.name: p for p in (FULL, QUICK, TINY)}


def accuracy_methods(plan, n):
    """Every method of the speed-against-accuracy sweep that fits a finest side of n."""
    from hcloth_ros.bench.scenarios import fits
    methods = [Method('explicit', 'explicit', (('strain_limit', None),))]
    for ext in ('exact', 'literal'):
        methods.append(Method(f'approx {ext}', 'approx', (('external', ext),)))
    for levels in plan.level_counts:
        if not fits(n, levels):
            continue
        for ext in ('exact', 'literal'):
            methods.append(Method(f'hierarchical {ext} L{levels}', 'hierarchical',
                                  (('external', ext),), levels))
    methods += multigrid_methods(n)
    for tol in plan.implicit_tolerances:
        methods.append(Method(f'implicit tol {tol:g} m', 'implicit',
                              (('tolerance', tol), ('strain_limit', None)),
                              max_n=plan.implicit_max_n, dts=plan.dts[:3]))
    return methods


def multigrid_levels(n):
    """Levels that make level 0 of an ``n x n`` cloth 9 x 9 (the node's default), or fewer."""
    from hcloth_ros.bench.scenarios import fits
    return next((lv for lv in range(6, 0, -1) if fits(n, lv) and (n - 1) // 2 ** (lv - 1) >= 8),
                1)


def multigrid_methods(n, backward_euler=True, levels=None):
    """
    List the accurate solver's variants on ``n x n`` points in ``levels``.

    Levels default to a 9 x 9 level 0. The variants: the default (BDF2 solved up to level
    1, eq. 7 above); the same solved on the finest level (no eq. 7, so no strain limiting
    either) when that is another level; with ``backward_euler``, the default with backward
    Euler: what BDF2 buys.
    """
    levels = multigrid_levels(n) if levels is None else levels
    methods = [Method(f'multigrid L{levels} (default)', 'multigrid', (), levels)]
    if levels > 2:
        methods.append(Method(f'multigrid L{levels} solved finest', 'multigrid',
                              (('accurate_level', None),), levels))
    if backward_euler:
        methods.append(Method(f'multigrid L{levels} backward Euler', 'multigrid',
                              (('integrator', 'backward_euler'),), levels))
    return methods


def stability_methods(plan):
    """List the solvers mapped over time step and stiffness (``n = plan.stability_n``)."""
    levels = 3 if plan.stability_n >= 9 else 2
    return [
        Method('explicit', 'explicit', (('strain_limit', None),)),
        Method('approx exact, no strain limit', 'approx', (('strain_limit', None),)),
        Method('approx exact, 10 % strain limit', 'approx'),
        Method(f'hierarchical exact L{levels}, no strain limit', 'hierarchical',
               (('strain_limit', None),), levels),
        Method(f'hierarchical exact L{levels}, 10 % strain limit', 'hierarchical',
               (), levels),
        Method(f'hierarchical literal L{levels}, 10 % strain limit', 'hierarchical',
               (('external', 'literal'),), levels),
        *multigrid_methods(plan.stability_n, backward_euler=False, levels=levels),
        # every other step down to 1/1920 s: Newton-CG at k = 1e5 costs ~1 min per run
        Method('implicit tol 1e-3 m', 'implicit', (('tolerance', 1e-3), ('strain_limit', None)),
               dts=tuple(dt for i, dt in enumerate(plan.stability_dts)
                         if i % 2 == 0 and dt >= 1 / 1920 * 0.999)),
    ]
