r"""
The immutable cloth model: a hierarchy of regular grids over one rectangle.

Level 0 is the coarse grid. Level k inserts a point on every edge of level k-1 (the
structural edges and one diagonal per quad, the "\" one from (r, c) to (r+1, c+1)), so
a side of level k has ``2**k * (n0 - 1) + 1`` points.

Two numberings of the same points exist:

* grid order (row-major over a level's ``(rows, cols)`` grid): what the kernels use,
  because a regular stencil over a grid vectorises far better than a general gather;
* point ids (the hierarchical numbering of the paper): level 0 points are ids
  ``0 .. n_0-1`` in grid order, and the points inserted by level k are ids
  ``n_{k-1} .. n_k-1`` in level-k grid order. So the first ``n_{k-1}`` ids of level k are
  exactly the points of level k-1, and an id means the same point at every level it exists
  on. Ids are the public numbering (pins, grasps, published clouds).

Units are SI: metres, kilograms, newtons per metre.
"""

from dataclasses import dataclass, field

# The 12-spring stencil of every grid point (row and column offsets, in pairs of opposite
# directions) is the kernels' (re-exported here); its spring kinds are below.
from hcloth_ros.core.kernels.layout import STENCIL_DC, STENCIL_DR, STENCIL_SIZE  # noqa: F401
import numpy as np

STENCIL_KIND = ('struct_u', 'struct_u', 'struct_v', 'struct_v', 'shear', 'shear',
                'shear', 'shear', 'bend_u', 'bend_u', 'bend_v', 'bend_v')


@dataclass(frozen=True)
class Placement:
    """
    Where the rest rectangle sits in the world frame at t = 0.

    A grid point at (row r, column c) of a level starts at
    ``origin + u * axis_u + v * axis_v`` with ``u = c * du`` and ``v = r * dv``.
    ``axis_u`` and ``axis_v`` must be orthonormal.
    """

    origin: tuple = (0.0, 0.0, 1.0)
    axis_u: tuple = (1.0, 0.0, 0.0)
    axis_v: tuple = (0.0, 1.0, 0.0)


@dataclass(frozen=True)
class Level:
    """
    One level of the hierarchy: a regular grid and its springs.

    Arrays are read-only. ``mass`` is the lumped mass of each grid point (kg), shape
    ``(rows, cols)``. ``rest`` and ``stiffness`` are per stencil direction (m, N/m), shape
    ``(12,)``. ``stiffness_sum`` is ``K_i``, the sum of nominal stiffness of the springs
    at each point (N/m), shape ``(rows, cols)``: the diagonal of the paper's Jacobian
    approximation.
    """

    index: int
    rows: int
    cols: int
    du: float
    dv: float
    mass: np.ndarray
    rest: np.ndarray
    stiffness: np.ndarray
    stiffness_sum: np.ndarray
    contraction: float
    point_count: int
    id_to_grid: np.ndarray = field(repr=False)
    grid_to_id: np.ndarray = field(repr=False)

    @property
    def shape(self):
        return (self.rows, self.cols)


def grid_triangles(rows, cols):
    """
    Triangles of a ``rows x cols`` grid as ``(2 * (rows-1) * (cols-1), 3)`` grid-order indices.

    Each quad ``(r, c)`` splits along its ``(r, c)-(r+1, c+1)`` diagonal (see
    :meth:`ClothModel.grid_triangles`).
    """
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing='ij')
    a = (r * cols + c).ravel()
    b = a + 1
    d = a + cols
    e = d + 1
    return np.stack([np.stack([a, e, b], 1), np.stack([a, d, e], 1)], 1).reshape(-1, 3)


class ClothModel:
    """
    Static data of a hierarchical cloth; build it with :class:`ClothBuilder`.

    :ivar levels: tuple of :class:`Level`, coarse to fine.
    :ivar level_count: number of levels.
    :ivar point_count: points of the finest level (ids ``0 .. point_count-1``).
    :ivar parents: int64 ``(point_count, 2)``: for an id inserted at level k >= 1, the two
        level k-1 ids of the edge it was inserted on; ``-1`` for level-0 ids.
    :ivar intro_level: int64 ``(point_count,)``: the level that inserts each id.
    :ivar total_mass: kg, the same at every level.
    :ivar gravity: m/s^2, shape ``(3,)``.
    :ivar air_drag: drag force per unit area and unit velocity (N s/m^3).
    :ivar spring_damping: damping of every spring along its direction (N s/m).
    """

    def __init__(self, width, height, placement, levels, parents, intro_level,
                 total_mass, gravity, scene, air_drag=0.0, spring_damping=0.0):
        self.width = float(width)
        self.height = float(height)
        self.placement = placement
        self.levels = tuple(levels)
        self.level_count = len(self.levels)
        self.point_count = self.levels[-1].point_count
        self.parents = parents
        self.intro_level = intro_level
        self.total_mass = float(total_mass)
        self.gravity = gravity
        self.scene = scene
        self.air_drag = float(air_drag)
        self.spring_damping = float(spring_damping)
        for array in (self.parents, self.intro_level, self.gravity):
            array.setflags(write=False)

    def level(self, k):
        if not 0 <= k < self.level_count:
            raise IndexError(f'level {k} out of range 0..{self.level_count - 1}')
        return self.levels[k]

    def rest_positions(self, k):
        """Return level k's initial positions, a ``(3, rows, cols)`` float64 array (SoA)."""
        lv = self.level(k)
        u = np.arange(lv.cols) * lv.du
        v = np.arange(lv.rows) * lv.dv
        origin = np.asarray(self.placement.origin, dtype=np.float64)
        au = np.asarray(self.placement.axis_u, dtype=np.float64)
        av = np.asarray(self.placement.axis_v, dtype=np.float64)
        q = (origin[:, None, None] + au[:, None, None] * u[None, None, :]
             + av[:, None, None] * v[None, :, None])
        return np.ascontiguousarray(q)

    def grid_triangles(self, k):
        """
        Triangles of level k as ``(2 * (rows-1) * (cols-1), 3)`` grid-order indices.

        Each quad is split along the same diagonal the hierarchy inserts points on, so a
        face-centre point of the next level lies on a triangle edge.
        """
        lv = self.level(k)
        return grid_triangles(lv.rows, lv.cols)

    def area_share(self, k):
        """Each level-k point's share of the cloth's area (m^2), shape ``(rows, cols)``."""
        return self.level(k).mass * (self.width * self.height / self.total_mass)

    def ids_at(self, k):
        """Ids of level k's points in grid order, shape ``(rows * cols,)``."""
        return self.level(k).grid_to_id.ravel()

    def anchor(self, point_id):
        """
        Return the coarser point that stands in for ``point_id`` one level below its own.

        For an inserted point this is the first of its two parents; level-0 points have
        no anchor (-1). Holding the anchor keeps the coarse levels from dragging a held
        fine point's neighbourhood away.
        """
        return int(self.parents[point_id, 0])

    def representative(self, point_id, k):
        """Return the id that stands for ``point_id`` on level k (itself if it exists)."""
        pid = int(point_id)
        while self.intro_level[pid] > k:
            pid = self.anchor(pid)
        return pid

    def footprint(self, point_id, k):
        """
        Return the level-k ids a grasp of ``point_id`` holds.

        The id itself where it exists, else the footprints of both end points of the edge
        it was inserted on.

        Holding only the first parent (the anchor) is not enough for a grasp: the other
        end point, free on the coarser level, sags away from the grasp, and on the finer
        level it is inherited (fixed) next to a held point, so the spring between them
        stretches without limit (67 % at a corner lifted 0.25 m, found in the fold demo).
        """
        pid = int(point_id)
        if self.intro_level[pid] <= k:
            return {pid}
        a, b = (int(p) for p in self.parents[pid])
        return self.footprint(a, k) | self.footprint(b, k)

    def grid_index(self, point_id, k):
        """Flat grid index of an id on level k (the id must exist on level k)."""
        lv = self.level(k)
        if not 0 <= point_id < lv.point_count:
            raise IndexError(f'point {point_id} does not exist on level {k} '
                             f'(ids 0..{lv.point_count - 1})')
        return int(lv.id_to_grid[point_id])


def _lumped_mass(rows, cols, total_mass):
    """Area-lumped masses: corners a quarter, edges a half of an interior point."""
    wu = np.ones(cols)
    wu[[0, -1]] = 0.5
    wv = np.ones(rows)
    wv[[0, -1]] = 0.5
    return total_mass * np.outer(wv, wu) / ((rows - 1) * (cols - 1))


def _stiffness_sum(rows, cols, stiffness):
    """K_i: the nominal stiffness of every spring that exists at each grid point."""
    total = np.zeros((rows, cols))
    for s in range(STENCIL_SIZE):
        dr, dc = STENCIL_DR[s], STENCIL_DC[s]
        r0, r1 = max(0, -dr), rows - max(0, dr)
        c0, c1 = max(0, -dc), cols - max(0, dc)
        if r1 > r0 and c1 > c0:
            total[r0:r1, c0:c1] += stiffness[s]
    return total


def _hierarchy_numbering(shapes):
    """Point ids per level (see the module docstring) and parents of inserted points."""
    grid_to_id = []
    rows0, cols0 = shapes[0]
    g0 = np.arange(rows0 * cols0, dtype=np.int64).reshape(rows0, cols0)
    grid_to_id.append(g0)
    parents = [np.full((rows0 * cols0, 2), -1, dtype=np.int64)]
    intro = [np.zeros(rows0 * cols0, dtype=np.int64)]
    next_id = rows0 * cols0
    for k in range(1, len(shapes)):
        rows, cols = shapes[k]
        coarse = grid_to_id[k - 1]
        g = np.full((rows, cols), -1, dtype=np.int64)
        g[0::2, 0::2] = coarse
        new_mask = g < 0
        count = int(new_mask.sum())
        g[new_mask] = np.arange(next_id, next_id + count)
        r, c = np.nonzero(new_mask)
        # Parent rule: odd row -> vertical edge, odd column -> horizontal edge, both odd
        # -> the quad's "\" diagonal. Integer halves of the neighbours give the parents.
        p0 = coarse[r // 2, c // 2]
        p1 = coarse[(r + 1) // 2, (c + 1) // 2]
        parents.append(np.stack([p0, p1], axis=1))
        intro.append(np.full(count, k, dtype=np.int64))
        next_id += count
        grid_to_id.append(g)
    return grid_to_id, np.concatenate(parents), np.concatenate(intro)


class ClothBuilder:
    """
    Collects a cloth description and turns it into a :class:`ClothModel`.

    :param width, height: the rest rectangle along ``axis_u`` and ``axis_v`` (m).
    :param resolution: level-0 points along u and v, e.g. ``(9, 9)``; each at least 2.
    :param level_count: number of levels (1 = a single grid).
    :param total_mass: kg, spread by area over every level's points.
    :param k_struct, k_shear, k_bend: spring stiffness (N/m) of structural, shear and
        bending springs on level 0.
    :param stiffness_scale: per-level factor on all three stiffnesses (default all 1: a
        spring of a regular grid represents the same membrane stiffness at any
        spacing, so N/m does not change with refinement).
    :param contraction: per-level contraction resistance c in [0, 1]: a compressed spring
        pushes back with c times its force (paper section IV).
    :param placement: :class:`Placement` of the rectangle at t = 0.
    :param gravity: m/s^2.
    :param scene: a :class:`hcloth_ros.core.scene.Scene` of static obstacles, or None.
    :param air_drag: air drag per unit area: a point moving at v feels
        ``-air_drag * area * v`` (N s/m^3; 0 = none). Read by the ``multigrid`` solver.
    :param spring_damping: every spring resists the rate of change of its length with
        this coefficient (N s/m; 0 = none). Read by the ``multigrid`` solver.
    """

    def __init__(self, width=1.0, height=1.0, resolution=(9, 9), level_count=3,
                 total_mass=0.2, k_struct=1000.0, k_shear=1000.0, k_bend=100.0,
                 stiffness_scale=None, contraction=None, placement=None,
                 gravity=(0.0, 0.0, -9.81), scene=None, air_drag=0.0, spring_damping=0.0):
        self.width = width
        self.height = height
        self.resolution = tuple(int(n) for n in np.broadcast_to(resolution, (2,)))
        self.level_count = int(level_count)
        self.total_mass = total_mass
        self.k = (k_struct, k_shear, k_bend)
        self.stiffness_scale = stiffness_scale
        self.contraction = contraction
        self.placement = placement or Placement()
        self.gravity = gravity
        self.scene = scene
        self.air_drag = air_drag
        self.spring_damping = spring_damping

    def _per_level(self, values, name, default, low, high):
        if values is None:
            values = [default] * self.level_count
        values = [float(v) for v in values]
        if len(values) != self.level_count:
            raise ValueError(f'{name} needs {self.level_count} values (one per level), '
                             f'got {len(values)}')
        for v in values:
            if not (low <= v <= high):
                raise ValueError(f'{name} value {v} outside [{low}, {high}]')
        return values

    def _validate(self):
        if not (np.isfinite(self.width) and np.isfinite(self.height)
                and self.width > 0 and self.height > 0):
            raise ValueError(f'cloth size must be positive, got {self.width} x {self.height} m')
        if min(self.resolution) < 2:
            raise ValueError(f'level-0 resolution needs at least 2 points a side, '
                             f'got {self.resolution}')
        if not 1 <= self.level_count <= 10:
            raise ValueError(f'level_count must be in 1..10, got {self.level_count}')
        if not (np.isfinite(self.total_mass) and self.total_mass > 0):
            raise ValueError(f'total_mass must be positive, got {self.total_mass}')
        if any(not (np.isfinite(k) and k >= 0) for k in self.k) or self.k[0] <= 0:
            raise ValueError(f'stiffness must be finite, non-negative and structural > 0, '
                             f'got {self.k}')
        for name in ('air_drag', 'spring_damping'):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 1e6):
                raise ValueError(f'{name} must be in [0, 1e6], got {value}')
        au = np.asarray(self.placement.axis_u, float)
        av = np.asarray(self.placement.axis_v, float)
        if (abs(np.linalg.norm(au) - 1) > 1e-9 or abs(np.linalg.norm(av) - 1) > 1e-9
                or abs(au @ av) > 1e-9):
            raise ValueError('placement axes must be orthonormal')

    def finalize(self):
        """Check everything and build the immutable model."""
        self._validate()
        scales = self._per_level(self.stiffness_scale, 'stiffness_scale', 1.0, 1e-6, 1e6)
        contraction = self._per_level(self.contraction, 'contraction', 1.0, 0.0, 1.0)
        shapes = []
        for k in range(self.level_count):
            rows = 2 ** k * (self.resolution[1] - 1) + 1
            cols = 2 ** k * (self.resolution[0] - 1) + 1
            shapes.append((rows, cols))
        grid_to_id, parents, intro = _hierarchy_numbering(shapes)
        kind_k = {'struct_u': self.k[0], 'struct_v': self.k[0], 'shear': self.k[1],
                  'bend_u': self.k[2], 'bend_v': self.k[2]}
        levels = []
        for k, (rows, cols) in enumerate(shapes):
            du = self.width / (cols - 1)
            dv = self.height / (rows - 1)
            kind_rest = {'struct_u': du, 'struct_v': dv, 'shear': float(np.hypot(du, dv)),
                         'bend_u': 2 * du, 'bend_v': 2 * dv}
            rest = np.array([kind_rest[kind] for kind in STENCIL_KIND])
            stiffness = np.array([kind_k[kind] for kind in STENCIL_KIND]) * scales[k]
            id_to_grid = np.empty(rows * cols, dtype=np.int64)
            id_to_grid[grid_to_id[k].ravel()] = np.arange(rows * cols)
            arrays = {'mass': _lumped_mass(rows, cols, self.total_mass), 'rest': rest,
                      'stiffness': stiffness,
                      'stiffness_sum': _stiffness_sum(rows, cols, stiffness),
                      'id_to_grid': id_to_grid, 'grid_to_id': grid_to_id[k]}
            for array in arrays.values():
                array.setflags(write=False)
            levels.append(Level(index=k, rows=rows, cols=cols, du=du, dv=dv,
                                contraction=contraction[k], point_count=rows * cols,
                                **arrays))
        return ClothModel(self.width, self.height, self.placement, levels, parents, intro,
                          self.total_mass, np.asarray(self.gravity, dtype=np.float64),
                          self.scene, self.air_drag, self.spring_damping)
