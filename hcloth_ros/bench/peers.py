"""
Our benchmark scene run in peer simulators (MuJoCo, PyBullet, Newton), for cost and plausibility.

The scene is the one our engine benchmarks: a 1 m x 1 m cloth of 0.2 kg on an n x n grid,
horizontal at z = 1.5 m, point ``(i, j)`` at ``x = -0.5 + i/(n-1)``, ``y = j/(n-1)``;
the two corners on ``y = 0`` pinned; gravity 9.81 m/s^2 along -z; no ground, no contact;
released at rest. Every result lists points in that order, flat index ``i * n + j``
(i-major: x outer, y inner).

Each peer is an optional extra, not a dependency::

    pip install mujoco==3.14.0 pybullet==3.2.7 newton==1.8.0 warp-lang==1.19.0

Newton is two peers, one per cloth solver: ``newton_vbd`` (Vertex Block Descent, implicit)
and ``newton_semi_implicit`` (symplectic Euler, explicit).

Only the stepping loop is timed (model building, kernel compilation and one warm-up step on
a throwaway copy of the scene are not), on one thread: no engine starts worker threads here
(MuJoCo steps single-threaded unless a thread pool is attached with ``mju_threadpool``,
which we never do; the PyPI PyBullet wheel is built without threading or OpenMP; Newton
runs on Warp's CPU device, whose kernels are a plain loop in the calling thread).
``cpu_seconds`` beside ``wall_seconds`` lets a reader check that: on one thread they are
about equal.

What each engine can and cannot copy of our springs is in its ``material`` string and in
the comments of its builder: MuJoCo has no springs for 2D flexes, so its continuum
membrane is fitted to our spring grid; PyBullet has springs but links every pair two
links apart as a bending spring and spreads the mass evenly over the nodes; Newton's VBD
and semi-implicit solvers both take arbitrary springs and per-particle masses, so they get
our spring grid and masses verbatim.
"""

import contextlib
import copy
import ctypes
import importlib
import importlib.metadata
import math
import os
import sys
import tempfile
import time
import warnings

import numpy as np

# --- the scene (SI units), identical to our benchmark's ---------------------------------

SIZE = 1.0            # m, side of the square cloth
TOTAL_MASS = 0.2      # kg
HEIGHT = 1.5          # m, initial z of the whole cloth
GRAVITY = 9.81        # m/s^2, along -z
K_STRUCT = 1000.0     # N/m, structural springs (grid neighbours)
K_SHEAR = 1000.0      # N/m, shear springs (both diagonals of every cell)
K_BEND = 100.0        # N/m, bending springs (two apart along a grid axis)

# pip command per Python package; Newton pins its Warp too (it accepts warp-lang>=1.17).
PIP_SPEC = {'mujoco': 'mujoco==3.14.0', 'pybullet': 'pybullet==3.2.7',
            'newton': 'newton==1.8.0 warp-lang==1.19.0', 'warp': 'warp-lang==1.19.0'}
# The Python package of each peer whose name is not its package's.
PEER_PACKAGE = {'newton_vbd': 'newton', 'newton_semi_implicit': 'newton'}

# MuJoCo: the shell thickness only sets the plate bending stiffness, since the membrane
# stiffness is fixed as the product E*t (see mujoco_membrane). 1 mm is cloth-like.
MUJOCO_THICKNESS = 1e-3   # m

# Newton's VBD: Gauss-Seidel sweeps over the vertex colours per step, its default number.
NEWTON_VBD_ITERATIONS = 10


# --- scene geometry, shared by every peer ------------------------------------------------

def grid_points(n):
    """Rest positions (m), shape ``(n*n, 3)``, flat index ``i * n + j``."""
    s = np.linspace(0.0, SIZE, n)
    x, y = np.meshgrid(s - SIZE / 2, s, indexing='ij')
    return np.stack([x.ravel(), y.ravel(), np.full(n * n, HEIGHT)], axis=1)


def pinned_indices(n):
    """Flat indices of the two pinned corners, (-0.5, 0) and (0.5, 0)."""
    return np.array([0, (n - 1) * n])


def lumped_masses(n):
    """
    Area-lumped point masses (kg) as in our engine, shape ``(n*n,)``.

    Corners a quarter and edge points half of an interior point, summing to TOTAL_MASS.
    """
    w = np.ones(n)
    w[[0, -1]] = 0.5
    return (TOTAL_MASS * np.outer(w, w) / (n - 1) ** 2).ravel()


def structural_edges(n):
    """
    Index pairs of the structural edges (grid neighbours), shape ``(2n(n-1), 2)``.

    Their rest length is ``SIZE / (n-1)``.
    """
    idx = np.arange(n * n).reshape(n, n)
    along_x = np.stack([idx[:-1, :].ravel(), idx[1:, :].ravel()], axis=1)
    along_y = np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], axis=1)
    return np.concatenate([along_x, along_y])


def spring_grid(n):
    """
    Our engine's springs: index pairs ``(m, 2)`` and stiffnesses (N/m) ``(m,)``.

    Structural (grid neighbours, K_STRUCT), shear (both diagonals of every cell, K_SHEAR)
    and bending (two apart along a grid axis, K_BEND); each rest length is the pair's
    distance in the flat grid.
    """
    idx = np.arange(n * n).reshape(n, n)
    shear = [np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()], axis=1),
             np.stack([idx[1:, :-1].ravel(), idx[:-1, 1:].ravel()], axis=1)]
    bend = [np.stack([idx[:-2, :].ravel(), idx[2:, :].ravel()], axis=1),
            np.stack([idx[:, :-2].ravel(), idx[:, 2:].ravel()], axis=1)]
    families = [(structural_edges(n), K_STRUCT), (np.concatenate(shear), K_SHEAR),
                (np.concatenate(bend), K_BEND)]
    pairs = np.concatenate([f for f, _ in families])
    stiffness = np.concatenate([np.full(len(f), k) for f, k in families])
    return pairs, stiffness


def sample_steps(dt, duration, sample_every):
    """
    Step counts at which to sample, without repeats.

    The step nearest to every multiple of ``sample_every`` from 0 to ``duration``
    inclusive.
    """
    count = int(math.floor(duration / sample_every + 1e-9))
    wanted = [k * sample_every for k in range(count + 1)]
    if duration - wanted[-1] > 1e-9:
        wanted.append(duration)
    steps = sorted({int(round(t / dt)) for t in wanted})
    return steps


def grid_order(points, n, tol=1e-6):
    """
    Permutation ``p`` with ``points[p]`` in our grid order.

    Found from the engine's initial vertex positions, so that no engine's internal
    numbering is assumed. Raises RuntimeError if the points are not our grid.
    """
    h = SIZE / (n - 1)
    i = np.rint((points[:, 0] + SIZE / 2) / h).astype(int)
    j = np.rint(points[:, 1] / h).astype(int)
    flat = i * n + j
    if (len(points) != n * n or np.any((i < 0) | (i >= n) | (j < 0) | (j >= n))
            or len(np.unique(flat)) != n * n):
        raise RuntimeError('the peer did not build the expected n x n grid')
    order = np.empty(n * n, dtype=int)
    order[flat] = np.arange(n * n)
    if np.abs(points[order] - grid_points(n)).max() > tol:
        raise RuntimeError('the peer moved the grid points from their rest positions')
    return order


# --- plumbing ------------------------------------------------------------------------------

@contextlib.contextmanager
def _silenced_output():
    """
    Send file descriptors 1 and 2 to /dev/null for the duration.

    PyBullet prints a banner from C at import, which would otherwise land in the
    benchmark's output. C's buffers are flushed before the descriptors are restored so
    nothing written meanwhile leaks out later.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in (1, 2)]
    try:
        with open(os.devnull, 'wb') as null:
            for fd in (1, 2):
                os.dup2(null.fileno(), fd)
        yield
    finally:
        with contextlib.suppress(Exception):
            ctypes.CDLL(None).fflush(None)
        for fd, copy_of in zip((1, 2), saved):
            os.dup2(copy_of, fd)
            os.close(copy_of)


def _import(name):
    """Import a peer's package (by package name), or raise ImportError naming the pip command."""
    try:
        if sys.modules.get(name) is not None:
            return sys.modules[name]
        with _silenced_output():               # PyBullet's banner comes at import
            return importlib.import_module(name)
    except ImportError as exc:
        raise ImportError(f'peer {name!r} needs its package: '
                          f'pip install {PIP_SPEC[name]}') from exc


def _version(name):
    return importlib.metadata.version(name)


def _simulate(step, positions, n, dt, duration, sample_every):
    """
    Step a built scene for ``duration`` and sample it.

    ``step()`` advances the engine by dt; ``positions()`` returns the current points in
    our grid order. Only the ``step()`` calls are timed. Stops early once a sample is not
    finite (nothing after a blow-up is worth simulating): later samples are NaN and the
    cost per simulated second is then taken over the time actually stepped.
    """
    total = int(round(duration / dt))
    at = [s for s in sample_steps(dt, duration, sample_every) if s <= total]
    edges = structural_edges(n)
    rest = SIZE / (n - 1)
    mass = lumped_masses(n)
    pins = pinned_indices(n)
    pins0 = grid_points(n)[pins]

    com_z = []
    max_strain = 0.0
    pin_drift = 0.0
    finite = True
    wall = cpu = 0.0
    done = 0
    x = positions()
    for s in at:
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(s - done):
            step()
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
        done = s
        x = positions()
        if not np.all(np.isfinite(x)):
            finite = False
            break
        stretch = np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1) / rest - 1.0
        max_strain = max(max_strain, float(stretch.max()))
        pin_drift = max(pin_drift, float(np.linalg.norm(x[pins] - pins0, axis=1).max()))
        # Our engine's centre of mass weights points by their area-lumped masses; the
        # same weights here make com_z the same function of the positions for every peer.
        com_z.append(float(mass @ x[:, 2] / mass.sum()))
    com_z += [math.nan] * (len(at) - len(com_z))
    return {
        'n': n, 'dt': dt, 'duration': duration, 'steps': total,
        'wall_seconds': wall, 'cpu_seconds': cpu,
        'wall_per_sim_second': wall / (done * dt) if done else math.nan,
        'finite': finite, 'max_strain': max_strain, 'pin_drift': pin_drift,
        'times': [s * dt for s in at], 'com_z': com_z,
        'positions_final': np.array(x, dtype=float),
    }


# --- MuJoCo --------------------------------------------------------------------------------

def spring_grid_moduli(k_struct=K_STRUCT, k_shear=K_SHEAR, k_bend=K_BEND):
    """
    In-plane elastic constants (N/m) of our spring grid, ``(C11, C12, G)``.

    The energy per unit area under a uniform small strain (ex, ey, exy) is
    ``W = C11/2 (ex^2 + ey^2) + C12 ex ey + 2 G exy^2``.

    Per cell of area h^2 there are, per axis, one structural spring (length h) and one
    bending spring (length 2h), and two shear springs (length h*sqrt(2)) stretched by
    ``(ex + ey)/2 +- exy``. Summing ``k/2 (L strain)^2`` over them and dividing by h^2:
    ``C11 = k_struct + k_shear + 4 k_bend``, ``C12 = k_shear``, ``G = k_shear``
    (2400, 1000 and 1000 N/m for ours; our engine's energy on a 65 x 65 grid confirms
    it to within the boundary's 1 %). The spacing cancels: the grid is a membrane whose
    stiffness does not change with n.
    """
    return k_struct + k_shear + 4 * k_bend, k_shear, k_shear


def mujoco_membrane(thickness=MUJOCO_THICKNESS):
    """
    Young's modulus (Pa) and Poisson's ratio of MuJoCo's 2D flex that best copy our grid.

    The flex copies our spring grid in plane: its stretch stiffness along the grid axes and
    its lateral contraction exactly, its shear to 70 %.

    MuJoCo 3.14 offers no edge springs on 2D flexes ("edge stiffness only available for
    dim=1"), only a continuum shell. Probing its membrane (affine strains of a flat flex,
    energy from the passive forces; test_peers repeats the probe) gives, per unit area,
    ``W = t/4 (mu e:e + lam tr(e)^2)`` with the 3D Lame constants
    ``mu = E/(2(1+nu))``, ``lam = E nu/((1+nu)(1-2nu))``, that is
    ``C11 = E t/(4(1+nu)(1-2nu))``, ``C12 = 2 nu C11``, ``G = E t/(8(1+nu))``.
    An isotropic membrane cannot copy the anisotropic spring grid, so we copy what a
    hanging cloth mostly does, stretch along a grid axis under uniaxial stress:

    - lateral contraction ``C12/C11``: springs 1000/2400 = 0.4167 = 2 nu -> nu = 0.2083;
    - uniaxial modulus ``C11 - C12^2/C11``: springs 2400 - 1000^2/2400 = 1983.3 N/m;
      MuJoCo ``E t (1+2nu)/(4(1+nu))`` -> E t = 4 * 1983.3 * 1.2083/1.4167 = 6766.7 N/m;
    - shear then comes out ``E t/(8(1+nu))`` = 700 N/m against the springs' 1000 N/m.

    The thickness only sets bending, ``D ~ E t^3/(12(1-nu^2))``: our bending springs
    have no small-curvature counterpart (a chord two cells long shortens by only
    kappa^2 h^3/3, so its energy is quartic in curvature and depends on h).
    """
    c11, c12, _ = spring_grid_moduli()
    nu = c12 / c11 / 2
    uniaxial = c11 - c12 ** 2 / c11
    e_t = 4 * uniaxial * (1 + nu) / (1 + 2 * nu)
    return e_t / thickness, nu


def _mujoco_xml(n, dt):
    """
    MJCF of the scene: one flexcomp grid, pinned corners, no contact.

    The ``discrete`` integrator is the one MuJoCo 3.14 requires for implicit flex
    elasticity (under ``implicit``/``implicitfast`` it refuses: "flex elasticity is no
    longer integrated implicitly ... set integrator='discrete'"); ``Euler`` integrates the
    membrane explicitly and blows up at dt = 1/960 s already at n = 9. Automatic reset is
    off so that a blow-up shows as non-finite positions instead of a silent restart.
    Elastic damping is 0: no damping beyond the integrator's own.
    """
    young, poisson = mujoco_membrane()
    h = SIZE / (n - 1)
    pins = ' '.join(str(int(p)) for p in pinned_indices(n))
    return f"""
<mujoco model="hcloth_peer">
  <option timestep="{dt!r}" gravity="0 0 {-GRAVITY!r}" integrator="discrete">
    <flag contact="disable" autoreset="disable"/>
  </option>
  <worldbody>
    <flexcomp name="cloth" type="grid" dim="2" count="{n} {n} 1" spacing="{h!r} {h!r} {h!r}"
              pos="0 {SIZE / 2!r} {HEIGHT!r}" mass="{TOTAL_MASS!r}" radius="0.001">
      <elasticity young="{young!r}" poisson="{poisson!r}" thickness="{MUJOCO_THICKNESS!r}"
                  elastic2d="both" damping="0"/>
      <contact selfcollide="none" internal="false" contype="0" conaffinity="0"/>
      <pin id="{pins}"/>
    </flexcomp>
  </worldbody>
</mujoco>
"""


def _mujoco_vertex_positions(mujoco, m, d):
    """
    Flex vertex positions of the current qpos.

    After mj_step the stored positions are those at the start of the step, so recompute
    kinematics (outside the timed loop).
    """
    mujoco.mj_kinematics(m, d)
    mujoco.mj_flex(m, d)
    return d.flexvert_xpos


def _mujoco_scene(mujoco, n, dt):
    """
    Compiled model and data at t = 0, plus the vertex order (see grid_order).

    flexcomp gives every body the same mass; we overwrite the free bodies' masses with
    our area-lumped ones so the scene's mass matches ours exactly (pinned corners sit on
    the world body and have no mass of their own).
    """
    m = mujoco.MjModel.from_xml_string(_mujoco_xml(n, dt))
    d = mujoco.MjData(m)
    order = grid_order(_mujoco_vertex_positions(mujoco, m, d).copy(), n)
    body = m.flex_vertbodyid[order]            # body of each point, in our order
    pinned = np.flatnonzero(body == 0)
    if not np.array_equal(pinned, pinned_indices(n)):
        raise RuntimeError(f'MuJoCo pinned points {pinned}, expected {pinned_indices(n)}')
    free = body != 0
    m.body_mass[body[free]] = lumped_masses(n)[free]
    mujoco.mj_setConst(m, d)
    mujoco.mj_resetData(m, d)
    return m, d, order


def run_mujoco(n, dt, duration=2.0, sample_every=1 / 30):
    """Run the scene in MuJoCo (flexcomp shell, discrete integrator); see run()."""
    mujoco = _import('mujoco')
    warnings = []
    previous = mujoco.get_mju_user_warning()
    # MuJoCo prints warnings (e.g. an under-converged implicit solve) to the console;
    # collect them into the result instead.
    mujoco.set_mju_user_warning(lambda text: warnings.append(str(text).strip()))
    try:
        m, d, order = _mujoco_scene(mujoco, n, dt)
        mujoco.mj_step(m, copy.copy(d))       # warm-up on a throwaway copy: not timed
        result = _simulate(lambda: mujoco.mj_step(m, d),
                           lambda: _mujoco_vertex_positions(mujoco, m, d)[order].copy(),
                           n, dt, duration, sample_every)
    finally:
        mujoco.set_mju_user_warning(previous)
    young, poisson = mujoco_membrane()
    result.update(
        peer='mujoco', version=_version('mujoco'),
        material=(f'flexcomp shell, elastic2d=both, E={young:.4g} Pa, nu={poisson:.4f}, '
                  f't={MUJOCO_THICKNESS:g} m: membrane E*t={young * MUJOCO_THICKNESS:.0f} N/m '
                  f'fitted to the springs (uniaxial 1983 N/m, contraction 0.417 exact; '
                  f'shear 700 vs 1000 N/m); bending from plate theory at t=1 mm; '
                  f'no damping; integrator=discrete'),
        mass_distribution='area-lumped as ours',
        threads='1 (no MuJoCo thread pool)',
        warnings=sorted(set(warnings)))
    return result


# --- PyBullet ------------------------------------------------------------------------------

def _pybullet_obj(n, path):
    """
    Write the grid as an .obj whose every cell holds both of its triangulations.

    Bullet makes one spring per mesh edge; both diagonals in the mesh give every cell our
    two shear springs (the overlapping faces only matter for contact, which is off).
    """
    with open(path, 'w') as f:
        for x, y, z in grid_points(n):
            f.write(f'v {x:.17g} {y:.17g} {z:.17g}\n')
        for i in range(n - 1):
            for j in range(n - 1):
                a, b = i * n + j + 1, (i + 1) * n + j + 1     # .obj counts from 1
                c, e = b + 1, a + 1
                f.write(f'f {a} {b} {c}\nf {a} {c} {e}\nf {a} {b} {e}\nf {b} {c} {e}\n')


def _pybullet_scene(p, n, dt):
    """
    Build the scene in a fresh DIRECT client; return (client, body, order).

    Deformable world, mass-spring model: ``springElasticStiffness`` on every mesh edge
    (our structural and shear springs), ``springBendingStiffness`` on Bullet's bending
    links, which it makes whenever that stiffness is nonzero (``useBendingSprings`` is
    ignored) between every pair two links apart: with both diagonals in the mesh that is
    16 partners per point (2 cells away along an axis, a knight's move or a diagonal)
    against our 4. No damping (``springDampingStiffness`` 0). Bullet sets the total mass
    evenly over the nodes (``setTotalMass`` without face weighting) and offers no
    per-node mass, so the edges carry more mass than ours. Pins are anchors to the world,
    which Bullet implements by giving the node zero inverse mass.
    """
    client = p.connect(p.DIRECT)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
    p.setGravity(0, 0, -GRAVITY, physicsClientId=client)
    p.setTimeStep(dt, physicsClientId=client)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'cloth.obj')
        _pybullet_obj(n, path)
        body = p.loadSoftBody(
            path, basePosition=[0, 0, 0], scale=1.0, mass=TOTAL_MASS,
            useMassSpring=1, useNeoHookean=0, useBendingSprings=1,
            springElasticStiffness=K_STRUCT, springBendingStiffness=K_BEND,
            springDampingStiffness=0.0, springDampingAllDirections=0,
            useSelfCollision=0, useFaceContact=0, frictionCoeff=0.0,
            collisionMargin=0.001, physicsClientId=client)
    order = grid_order(_pybullet_positions(p, client, body), n)
    for k in pinned_indices(n):
        p.createSoftBodyAnchor(body, int(order[k]), -1, -1, physicsClientId=client)
    return client, body, order


def _pybullet_positions(p, client, body):
    _, points = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                              physicsClientId=client)
    return np.array(points, dtype=float)


def run_pybullet(n, dt, duration=2.0, sample_every=1 / 30):
    """Run the scene in PyBullet (deformable world, mass-spring); see run()."""
    p = _import('pybullet')
    # Warm-up: one step of a throwaway copy of the scene in its own client, not timed.
    client, _, _ = _pybullet_scene(p, n, dt)
    p.stepSimulation(physicsClientId=client)
    p.disconnect(client)
    client, body, order = _pybullet_scene(p, n, dt)
    try:
        result = _simulate(lambda: p.stepSimulation(physicsClientId=client),
                           lambda: _pybullet_positions(p, client, body)[order],
                           n, dt, duration, sample_every)
    finally:
        p.disconnect(client)
    result.update(
        peer='pybullet', version=_version('pybullet'),
        material=(f'deformable mass-spring: {K_STRUCT:g} N/m on every mesh edge '
                  f'(structural + both shear diagonals, as ours), {K_BEND:g} N/m on '
                  f"Bullet's bending links (all pairs two links apart: 16 per point vs "
                  f'our 4), no damping; semi-implicit (Bullet default, implicit off)'),
        mass_distribution='uniform per node (Bullet has no per-node mass); ours is area-lumped',
        threads='1 (wheel built without threading)',
        warnings=[])
    return result


# --- Newton ----------------------------------------------------------------------------------

def newton_colors(n):
    """
    Vertex colouring for Newton's VBD: lists of flat indices, no spring within a colour.

    VBD updates the points of one colour at a time, in parallel on a GPU, so no two points
    of a colour may share an element. Newton's own ``ModelBuilder.color`` looks only at
    triangles, bending edges and tetrahedra, not at springs, so we colour by
    ``(i mod 3, j mod 3)``: every spring of spring_grid joins points 1 or 2 apart along
    an axis or diagonally, which always differ in one of those. Nine colours.
    """
    i, j = np.divmod(np.arange(n * n), n)
    color = (i % 3) * 3 + j % 3
    return [np.flatnonzero(color == c) for c in range(9) if np.any(color == c)]


def _newton_scene(newton, n, solver):
    """
    Build the scene on Warp's CPU device; return (model, engine, order).

    ``engine`` is the Newton solver named by ``solver``, ``order`` as from grid_order.

    Both of Newton's cloth solvers take springs (``Model.spring_*``: Hooke springs on the
    distance, rest length from the initial positions) besides their FEM triangles and
    dihedral bending edges, so we give them our springs one for one (spring_grid), with our
    area-lumped masses (particles added one by one with their mass) and no triangles or
    bending edges at all. Newton's ``add_cloth_grid`` would not do: it splits each cell
    along one diagonal only, lumps the mass by triangle area (so a cell's corners get
    unequal shares) and its optional springs are that mesh's edges and bending pairs, not
    ours. A fitted continuum membrane (VBD's StVK/Neo-Hookean triangles with tri_ke/tri_ka
    and edge_ke bending) would also lose our grid's anisotropy (see mujoco_membrane), which
    springs keep exactly. No damping (spring kd 0), particle radius 0 (which leaves the
    model without its particle hash grid: no particle-particle contact), no shapes, so
    nothing collides. The pinned corners are kinematic as in ``add_cloth_grid``'s
    ``fix_*``: mass 0 and the ACTIVE flag cleared.
    """
    builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, -GRAVITY))
    pinned = np.zeros(n * n, dtype=bool)
    pinned[pinned_indices(n)] = True
    active = int(newton.ParticleFlags.ACTIVE)
    builder.add_particles(grid_points(n).tolist(), [(0.0, 0.0, 0.0)] * (n * n),
                          np.where(pinned, 0.0, lumped_masses(n)).tolist(),
                          radius=[0.0] * (n * n),
                          flags=[0 if p else active for p in pinned])
    pairs, stiffness = spring_grid(n)
    for (i, j), k in zip(pairs.tolist(), stiffness.tolist()):
        builder.add_spring(i, j, k, 0.0, 0.0)
    if solver == 'vbd':
        builder.set_coloring(newton_colors(n))
    model = builder.finalize(device='cpu')
    if model.particle_grid is not None:
        raise RuntimeError('Newton built a particle contact grid for the cloth')
    if solver == 'vbd':
        # Implicit Euler, minimised by NEWTON_VBD_ITERATIONS sweeps of per-vertex Newton
        # steps; self-contact off (the default), so no collision detection either.
        engine = newton.solvers.SolverVBD(model, iterations=NEWTON_VBD_ITERATIONS,
                                          particle_enable_self_contact=False)
    else:
        # Symplectic Euler (v += a dt, then x += v dt): the springs are explicit.
        engine = newton.solvers.SolverSemiImplicit(model, enable_tri_contact=False)
    order = grid_order(model.particle_q.numpy().astype(float), n)
    return model, engine, order


def _newton_stepper(wp, model, engine, dt):
    """
    Return (step, positions) for a built scene, its steps recorded as CPU graphs.

    Newton's solvers step ``state_in`` into ``state_out``; two states alternate. Each of
    the two steps (0 into 1, 1 into 0) is recorded once as a Warp graph, which on the CPU
    Warp replays in C++ (``capture_launch``), without the Python of a launch per kernel:
    that is how Newton's own examples step. A VBD step is 273 kernel launches, a
    semi-implicit one 2 behind a lot of Python; replayed, either steps about 20 times
    faster than launched from Python at n = 9, 3-4 times at n = 33. Recording runs
    nothing, so the states are still at t = 0 afterwards. Forces accumulate in
    ``particle_f``, so every step clears them first, as Newton's examples do.
    """
    states = [model.state(), model.state()]
    control = model.control()
    graphs = []
    for a, b in ((0, 1), (1, 0)):
        with wp.ScopedCapture(device='cpu') as capture:
            states[a].clear_forces()
            engine.step(states[a], states[b], control, None, dt)
        graphs.append(capture.graph)
    current = [0]

    def step():
        wp.capture_launch(graphs[current[0]])
        current[0] ^= 1

    def positions():
        return states[current[0]].particle_q.numpy()

    return step, positions


def _run_newton(solver, n, dt, duration, sample_every):
    """
    Run the scene in Newton with ``solver`` ('vbd' or 'semi_implicit'); see run().

    Warp compiles each kernel module to C++ on its first use on a device (seconds per
    module; cached on disk, in Warp's kernel cache: ``$WARP_CACHE_PATH`` or else the user
    cache, ``~/.cache/warp/<version>``) and prints its progress: that happens in the
    silenced, untimed warm-up on a throwaway copy of the scene. Newton computes in float32.
    Python warnings from Newton or Warp are collected into the result.
    """
    newton = _import('newton')
    wp = _import('warp')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        with _silenced_output():
            wp.init()                          # prints a banner, on a CPU-only host a warning
        with wp.ScopedDevice('cpu'):
            # Warm-up: one step of a throwaway copy of the scene, not timed; it compiles
            # (or loads from the cache) every kernel the step launches.
            with _silenced_output():
                warm_step, _ = _newton_stepper(wp, *_newton_scene(newton, n, solver)[:2], dt)
                warm_step()
                model, engine, order = _newton_scene(newton, n, solver)
                step, positions = _newton_stepper(wp, model, engine, dt)
            result = _simulate(step, lambda: positions()[order].astype(float),
                               n, dt, duration, sample_every)
    springs = (f'our springs one for one as Newton springs: {K_STRUCT:g} N/m structural, '
               f'{K_SHEAR:g} N/m on both diagonals of every cell, {K_BEND:g} N/m bending '
               f'two apart along an axis; no FEM triangles or dihedral bending; no damping')
    if solver == 'vbd':
        method = (f'SolverVBD: implicit Euler by {NEWTON_VBD_ITERATIONS} vertex block '
                  f'descent iterations per step (Newton default), 9-colour grid colouring')
    else:
        method = 'SolverSemiImplicit: symplectic Euler, springs explicit'
    result.update(
        peer=f'newton_{solver}', version=_version('newton'),
        material=(f'{springs}; {method}; float32; Warp {_version("warp-lang")} CPU, '
                  f'steps replayed as CPU graphs'),
        mass_distribution='area-lumped as ours',
        threads='1 (Warp CPU kernels are a serial loop in the calling thread)',
        warnings=sorted({str(w.message).strip() for w in caught}))
    return result


def run_newton_vbd(n, dt, duration=2.0, sample_every=1 / 30):
    """Run the scene in Newton's VBD cloth solver (our springs, implicit); see run()."""
    return _run_newton('vbd', n, dt, duration, sample_every)


def run_newton_semi_implicit(n, dt, duration=2.0, sample_every=1 / 30):
    """Run the scene in Newton's semi-implicit solver (our springs, explicit); see run()."""
    return _run_newton('semi_implicit', n, dt, duration, sample_every)


# --- the API the benchmark uses --------------------------------------------------------------

PEERS = {'mujoco': run_mujoco, 'pybullet': run_pybullet, 'newton_vbd': run_newton_vbd,
         'newton_semi_implicit': run_newton_semi_implicit}


def available():
    """Names of the peers whose Python package imports here (others are skipped, not errors)."""
    names = []
    for name in PEERS:
        try:
            _import(PEER_PACKAGE.get(name, name))
        except ImportError:
            continue
        names.append(name)
    return names


def run(name, n, dt, duration=2.0, sample_every=1 / 30):
    """
    Run the scene once in peer ``name`` at time step ``dt`` (s).

    Returns a dict with: ``peer``, ``version``, ``n``, ``dt``, ``duration``, ``steps``,
    ``material`` (the material mapping used), ``mass_distribution``, ``threads``,
    ``wall_seconds`` and ``cpu_seconds`` (the stepping loop only: building and one
    warm-up step excluded), ``wall_per_sim_second`` (wall_seconds / duration; over the
    time actually stepped if a blow-up to non-finite positions stopped the run early),
    ``finite`` (every sample finite), ``max_strain`` (largest ``|x_i - x_j| / L - 1``
    over the structural edges and the samples), ``pin_drift`` (m, largest distance of a
    pinned corner from its start), ``times`` (s, every ``sample_every`` from 0 to
    ``duration``, at the nearest step), ``com_z`` (m, centre-of-mass height with our
    area-lumped masses at those times; NaN after a blow-up), ``positions_final``
    (``(n*n, 3)`` array, flat index ``i * n + j``, see the module docstring) and
    ``warnings`` (the engine's, deduplicated).

    Raises ValueError for an unknown name, ImportError (with the pip command) if the
    peer's package is missing.
    """
    if name not in PEERS:
        raise ValueError(f'unknown peer {name!r}; known: {sorted(PEERS)}')
    if n < 2 or not dt > 0 or not duration > 0 or not sample_every > 0:
        raise ValueError('need n >= 2 and positive dt, duration and sample_every')
    return PEERS[name](int(n), float(dt), float(duration), float(sample_every))


def largest_plausible_step(name, n, dts=(1 / 30, 1 / 60, 1 / 120, 1 / 240, 1 / 480, 1 / 960,
                                         1 / 1920),
                           strain_bound=0.2, duration=2.0, on_run=None):
    """
    Find the largest time step at which the peer's run is plausible.

    Tries ``dts`` from largest to smallest and returns the result (as from run) of the
    first run that is finite with ``max_strain <= strain_bound``, with ``plausible``
    True; if none is, the smallest dt's result with ``plausible`` False. Either way
    ``tried`` lists ``{dt, finite, max_strain, wall_per_sim_second}`` of every run made.
    ``on_run(result)`` is called after every run (progress reporting).
    """
    tried = []
    result = None
    for dt in sorted(dts, reverse=True):
        result = run(name, n, dt, duration=duration)
        tried.append({key: result[key]
                      for key in ('dt', 'finite', 'max_strain', 'wall_per_sim_second')})
        result['plausible'] = result['finite'] and result['max_strain'] <= strain_bound
        if on_run is not None:
            on_run(result)
        if result['plausible']:
            break
    result['tried'] = tried
    return result
