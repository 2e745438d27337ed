"""
The benchmark's scenes and the one loop that runs a solver through them.

Every scenario is a 1 m x 1 m, 0.2 kg cloth released at rest from horizontal at 1.5 m,
with no obstacles (contact is not what is measured here):

* ``swing``: pinned at the two corners on y = 0; it swings down and back.
* ``free_fall``: nothing holds it; the exact answer is known in closed form.
* ``grasp``: the same two corners grasped and carried 0.4 m along x and 0.3 m up along a
  smooth (cosine) profile during the first second, then held.

A run is identified by the finest mesh (``n`` points a side) and the level count, so a
hierarchical solver with 2, 3 or 4 levels and a single-level solver share the same finest
mesh and the same reference.
"""

from dataclasses import dataclass
import time

from hcloth_ros.core import ClothBuilder, Control, make_solver, Placement, State
from hcloth_ros.core.metrics import centre_of_mass, energy
import numpy as np

SCENARIOS = ('swing', 'free_fall', 'grasp')
SAMPLE_EVERY = 1 / 30      # s between samples; every time step used divides it
GRASP_MOVE = np.array([0.4, 0.0, 0.3])     # m, carried during GRASP_SECONDS
GRASP_SECONDS = 1.0


def level0_side(n, levels):
    """Level-0 points a side for a finest side of ``n`` points and ``levels`` levels."""
    n0, rem = divmod(n - 1, 2 ** (levels - 1))
    if rem or n0 < 1:
        raise ValueError(f'a finest side of {n} points cannot be split into {levels} levels')
    return n0 + 1


def fits(n, levels):
    """Whether a finest side of ``n`` points splits into ``levels`` levels."""
    try:
        level0_side(n, levels)
        return True
    except ValueError:
        return False


def build_model(n, levels=1, k=1000.0, contraction=None, scene=None):
    """
    Build the benchmark cloth, finest ``n x n``.

    Structural and shear springs ``k``, bending ``k / 10`` (N/m, the default scene's ratio);
    no obstacles unless a ``scene`` is given.
    """
    n0 = level0_side(n, levels)
    return ClothBuilder(width=1.0, height=1.0, resolution=(n0, n0), level_count=levels,
                        total_mass=0.2, k_struct=k, k_shear=k, k_bend=k / 10,
                        contraction=contraction, scene=scene,
                        placement=Placement((-0.5, 0.0, 1.5), (1, 0, 0), (0, 1, 0))).finalize()


def corner_ids(model):
    """Ids of the two corners on y = 0 (level-0 points, so they exist on every level)."""
    return [0, model.level(0).cols - 1]


def grasp_offset(t):
    """Where the grasp has carried the corners at time t (m)."""
    s = 0.5 * (1 - np.cos(np.pi * min(t, GRASP_SECONDS) / GRASP_SECONDS))
    return GRASP_MOVE * s


# violent grasp motions of the corners (offset from the start, m, at time t): what a
# teleoperated or badly tuned robot does
VIOLENT = {
    'grasp_jump': lambda t: np.array([0.0, 0.0, 0.3]) if t > 0.1 else np.zeros(3),
    'grasp_fast': lambda t: np.array([0.0, 5.0 * min(max(t - 0.1, 0.0), 0.1), 0.0]),
    'grasp_shake': lambda t: np.array([0.0, 0.0, 0.1 * np.sin(2 * np.pi * 3 * t)]),
}
VIOLENT_TEXT = {'grasp_jump': 'jumps 0.3 m up in one step',
                'grasp_fast': 'moves 0.5 m sideways at 5 m/s',
                'grasp_shake': 'shakes 0.1 m up and down at 3 Hz'}
MOTIONS = {'grasp': grasp_offset, **VIOLENT}


@dataclass
class Setup:
    """A scenario applied to one model: its control and what to do before each step."""

    control: Control
    drive: object = None        # drive(t_end_of_step) or None


def prepare(scenario, model, state):
    control = Control(model)
    if scenario == 'swing':
        control.set_pins(corner_ids(model))
        return Setup(control)
    if scenario == 'free_fall':
        return Setup(control)
    if scenario in MOTIONS:
        offset = MOTIONS[scenario]
        control.grasp('hands', corner_ids(model), state)
        return Setup(control, lambda t: control.move_grasp('hands', np.eye(3), offset(t)))
    raise ValueError(f'unknown scenario {scenario!r}; choose one of '
                     f'{SCENARIOS + tuple(VIOLENT)}')


@dataclass
class Run:
    """One simulation: samples every SAMPLE_EVERY s of the finest level, from t = 0."""

    scenario: str
    solver: str
    options: dict
    n: int
    levels: int
    dt: float
    duration: float
    times: np.ndarray = None
    points: np.ndarray = None       # (samples, n*n, 3) finest level, grid order
    com: np.ndarray = None          # (samples, 3)
    energy: np.ndarray = None       # (samples,) kinetic + gravity + elastic (J)
    max_strain: float = 0.0
    wall: float = 0.0               # s spent in stepping (and driving) only
    failed: str = ''                # why the run stopped early ('' if it did not)

    @property
    def wall_per_sim_second(self):
        return self.wall / max(self.times[-1], self.dt) if self.times is not None else np.nan


def samples_per(dt, duration):
    """Return (steps, steps between samples) for a step dt that divides SAMPLE_EVERY."""
    every = SAMPLE_EVERY / dt
    if abs(every - round(every)) > 1e-6 or round(every) < 1:
        raise ValueError(f'dt = {dt} must divide the sample interval {SAMPLE_EVERY:.5f} s')
    every = int(round(every))
    return int(round(duration / SAMPLE_EVERY)) * every, every


def simulate(scenario, solver_name, n, levels, dt, duration, k=1000.0, options=None,
             contraction=None):
    """Run one solver through one scenario; a refused step ends the run (``failed``)."""
    options = dict(options or {})
    model = build_model(n, levels, k, contraction)
    solver = make_solver(solver_name, model, **options)
    state = State.at_rest(model)
    setup = prepare(scenario, model, state)
    top = model.level_count - 1
    steps, every = samples_per(dt, duration)
    run = Run(scenario, solver_name, options, n, levels, dt, duration)
    times, points, com, ener = [], [], [], []

    def sample():
        times.append(state.time)
        points.append(state.points(top).astype(np.float32))
        com.append(centre_of_mass(model, state, top))
        ener.append(sum(energy(model, state, top)))

    sample()
    wall = 0.0
    for i in range(1, steps + 1):
        start = time.perf_counter()
        if setup.drive is not None:
            setup.drive(state.time + dt)
        report = solver.step(state, setup.control, dt)
        wall += time.perf_counter() - start
        if not report.ok:
            run.failed = f't = {state.time + dt:.3f} s: {report.reason}'
            break
        run.max_strain = max(run.max_strain, report.max_strain)
        if i % every == 0:
            sample()
    run.times, run.points = np.array(times), np.array(points)
    run.com, run.energy, run.wall = np.array(com), np.array(ener), wall
    return run


def closed_form_free_fall(n, duration, g=9.81):
    """Return the exact free fall: every point falls g t^2 / 2 and the cloth keeps its shape."""
    model = build_model(n, 1)
    rest = State.at_rest(model).points(0)
    steps, _ = samples_per(SAMPLE_EVERY, duration)
    times = np.arange(steps + 1) * SAMPLE_EVERY
    drop = np.zeros((len(times), 1, 3))
    drop[:, 0, 2] = -0.5 * g * times ** 2
    points = rest[None] + drop
    mass = model.level(0).mass.ravel()
    com = np.einsum('spd,p->sd', points, mass) / mass.sum()
    # nothing stretches and gravity's work becomes kinetic energy: the total stays put
    total = np.full(len(times), sum(energy(model, State.at_rest(model), 0)))
    return Run('free_fall', 'closed form', {}, n, 1, 0.0, duration, times=times,
               points=points, com=com, energy=total)
