"""
The hierarchy of grids (paper section IV): counts, numbering, parents, masses, LOD.

The model is deliberately non-square (3 points along u, 4 along v, and a rectangle of
0.6 m x 0.9 m) and placed with a tilted frame, so that any mix-up of rows and columns, or
of width and height, changes a number that is asserted here.
"""

from hcloth_ros.core import ClothBuilder, Placement, State
from hcloth_ros.core import kernels
from hcloth_ros.core.model import STENCIL_DC, STENCIL_DR
import numpy as np
import pytest

WIDTH, HEIGHT = 0.6, 0.9        # m, along axis_u (columns) and axis_v (rows)
RES = (3, 4)                    # level-0 points along u, along v
LEVELS = 3
TOTAL_MASS = 0.37               # kg
EPS = np.finfo(float).eps


def _tilted_placement():
    a, b = 0.3, 0.2
    axis_u = (np.cos(a), np.sin(a), 0.0)
    axis_v = (-np.sin(a) * np.cos(b), np.cos(a) * np.cos(b), np.sin(b))
    return Placement(origin=(0.1, -0.3, 1.7), axis_u=axis_u, axis_v=axis_v)


@pytest.fixture(scope='module')
def model():
    return ClothBuilder(width=WIDTH, height=HEIGHT, resolution=RES, level_count=LEVELS,
                        total_mass=TOTAL_MASS, placement=_tilted_placement()).finalize()


@pytest.fixture(scope='module')
def rest(model):
    return State.at_rest(model)


def _uv(model, points):
    """Rest-frame coordinates (u, v) of world points, shape (n, 2)."""
    pl = model.placement
    rel = points - np.asarray(pl.origin)
    return np.stack([rel @ np.asarray(pl.axis_u), rel @ np.asarray(pl.axis_v)], axis=1)


def test_point_counts_per_level(model):
    # Level k inserts a point on every edge of level k-1: a side of n0 points becomes
    # 2^k (n0 - 1) + 1 points. Columns run along u (resolution[0]), rows along v.
    assert model.level_count == LEVELS
    for k in range(LEVELS):
        lv = model.level(k)
        cols = 2 ** k * (RES[0] - 1) + 1
        rows = 2 ** k * (RES[1] - 1) + 1
        assert (lv.rows, lv.cols) == (rows, cols)
        assert lv.point_count == rows * cols
        assert model.ids_at(k).shape == (rows * cols,)
        # the grid spacing divides the right side of the rectangle
        assert lv.du == pytest.approx(WIDTH / (cols - 1), rel=1e-15)
        assert lv.dv == pytest.approx(HEIGHT / (rows - 1), rel=1e-15)
    assert [model.level(k).point_count for k in range(LEVELS)] == [12, 35, 117]
    assert model.point_count == 117
    assert model.parents.shape == (117, 2)
    # intro_level counts: n_0 ids at level 0, n_k - n_{k-1} ids at level k
    counts = np.bincount(model.intro_level, minlength=LEVELS)
    assert counts.tolist() == [12, 35 - 12, 117 - 35]


def test_rest_positions_span_the_rectangle(model, rest):
    # The rest grid of every level spans exactly [0, W] x [0, H] in (u, v): the extreme
    # columns are 0 and (cols-1) du = W up to rounding (a few ulp of the coordinates).
    for k in range(LEVELS):
        lv = model.level(k)
        uv = _uv(model, rest.points(k)).reshape(lv.rows, lv.cols, 2)
        tol = 8 * EPS * 3.0
        np.testing.assert_allclose(uv[:, 0, 0], 0.0, atol=tol)
        np.testing.assert_allclose(uv[:, -1, 0], WIDTH, atol=tol)
        np.testing.assert_allclose(uv[0, :, 1], 0.0, atol=tol)
        np.testing.assert_allclose(uv[-1, :, 1], HEIGHT, atol=tol)


def test_id_numbering_is_a_bijection(model):
    for k in range(LEVELS):
        lv = model.level(k)
        assert np.array_equal(np.sort(lv.grid_to_id.ravel()), np.arange(lv.point_count))
        assert np.array_equal(lv.grid_to_id.ravel()[lv.id_to_grid],
                              np.arange(lv.point_count))


def test_first_ids_of_a_level_are_the_coarser_level(model, rest):
    # Paper: "the first n_{k-1} points of level k are exactly the points of level k-1".
    # The same point has the same rest position at both levels, bit for bit (level k's
    # spacing is exactly half of level k-1's: a division by a power of two is exact).
    for k in range(1, LEVELS):
        n_prev = model.level(k - 1).point_count
        fine = rest.points_by_id(model, k)
        coarse = rest.points_by_id(model, k - 1)
        assert np.array_equal(fine[:n_prev], coarse)
        # and they sit on the even rows and columns of level k's grid
        assert np.array_equal(model.level(k).grid_to_id[0::2, 0::2],
                              model.level(k - 1).grid_to_id)
        # inserted ids are n_{k-1} .. n_k - 1, introduced by level k
        assert np.all(model.intro_level[n_prev:model.level(k).point_count] == k)


def test_parents_are_the_inserted_points_edge(model, rest):
    # Every inserted point sits at the midpoint of a level k-1 edge: a structural edge
    # (length du_{k-1} or dv_{k-1}) or the quad's "\" diagonal from (r, c) to
    # (r+1, c+1) (length hypot(du, dv)). Coordinates are O(1) m, so 1e-12 m is ~1e4 ulp
    # of slack for the rounding of the two rest-position formulas.
    parents = model.parents
    assert np.all(parents[:model.level(0).point_count] == -1)
    kinds_seen = set()
    for k in range(1, LEVELS):
        lv, lp = model.level(k), model.level(k - 1)
        n_prev, n_k = lp.point_count, lv.point_count
        fine = rest.points_by_id(model, k)
        coarse = rest.points_by_id(model, k - 1)
        for pid in range(n_prev, n_k):
            p0, p1 = parents[pid]
            assert 0 <= p0 < n_prev and 0 <= p1 < n_prev and p0 != p1
            assert model.intro_level[p0] <= k - 1 and model.intro_level[p1] <= k - 1
            mid = 0.5 * (coarse[p0] + coarse[p1])
            np.testing.assert_allclose(fine[pid], mid, rtol=0, atol=1e-12)
            # the edge, in level k-1 grid steps
            g0, g1 = lp.id_to_grid[p0], lp.id_to_grid[p1]
            dr = g1 // lp.cols - g0 // lp.cols
            dc = g1 % lp.cols - g0 % lp.cols
            assert (dr, dc) in {(0, 1), (1, 0), (1, 1)}, (pid, dr, dc)
            length = np.linalg.norm(coarse[p1] - coarse[p0])
            expected = {(0, 1): lp.du, (1, 0): lp.dv, (1, 1): np.hypot(lp.du, lp.dv)}
            assert length == pytest.approx(expected[(dr, dc)], abs=1e-12)
            kinds_seen.add((dr, dc))
            # the grid parity decides the edge: odd row -> v edge, odd col -> u edge
            g = lv.id_to_grid[pid]
            r, c = g // lv.cols, g % lv.cols
            assert (dr, dc) == (r % 2, c % 2)
    assert kinds_seen == {(0, 1), (1, 0), (1, 1)}
    # each level k-1 edge gets exactly one point: number of inserted points =
    # horizontal + vertical + diagonal edges of level k-1
    for k in range(1, LEVELS):
        lp = model.level(k - 1)
        edges = (lp.rows * (lp.cols - 1) + (lp.rows - 1) * lp.cols
                 + (lp.rows - 1) * (lp.cols - 1))
        assert model.level(k).point_count - lp.point_count == edges
        pairs = {tuple(p) for p in model.parents[lp.point_count:model.level(k).point_count]}
        assert len(pairs) == edges


def test_masses_sum_to_total_at_every_level(model):
    # Area-lumped masses: every level carries the whole cloth (same total mass), and a
    # corner holds a quarter, an edge point a half of an interior point's mass.
    for k in range(LEVELS):
        lv = model.level(k)
        assert lv.mass.shape == (lv.rows, lv.cols)
        assert lv.mass.sum() == pytest.approx(TOTAL_MASS, rel=1e-12)
        interior = TOTAL_MASS / ((lv.rows - 1) * (lv.cols - 1))
        assert lv.mass[1, 1] == pytest.approx(interior, rel=1e-14)
        assert lv.mass[0, 0] == pytest.approx(interior / 4, rel=1e-14)
        assert lv.mass[0, 1] == pytest.approx(interior / 2, rel=1e-14)
        assert lv.mass[1, 0] == pytest.approx(interior / 2, rel=1e-14)


def test_stiffness_sum_counts_existing_springs(model):
    # K_i (Jacobian diagonal) of an interior point far from the border has all 12
    # springs: 4 structural + 4 shear + 4 bending; a corner has 2 + 1 + 2.
    lv = model.level(2)
    k_struct, k_shear, k_bend = 1000.0, 1000.0, 100.0    # builder defaults
    assert lv.stiffness_sum[2, 2] == pytest.approx(4 * k_struct + 4 * k_shear + 4 * k_bend,
                                                   rel=1e-15)
    assert lv.stiffness_sum[0, 0] == pytest.approx(2 * k_struct + k_shear + 2 * k_bend,
                                                   rel=1e-15)
    # the sum over points of K_i counts every spring twice
    springs = 0.0
    for s in range(0, 12, 2):
        dr, dc = abs(STENCIL_DR[s]), abs(STENCIL_DC[s])
        springs += lv.stiffness[s] * (lv.rows - dr) * (lv.cols - dc)
    assert lv.stiffness_sum.sum() == pytest.approx(2 * springs, rel=1e-13)


def test_grid_triangles_cover_the_rectangle(model, rest):
    # The triangulation of each level tiles the rectangle: the areas add up to W * H
    # (1e-12 relative: sums of 2 (rows-1)(cols-1) cross products of O(1) numbers), each
    # triangle has the same area du dv / 2, and all normals point the same way.
    for k in range(LEVELS):
        lv = model.level(k)
        tri = model.grid_triangles(k)
        assert tri.shape == (2 * (lv.rows - 1) * (lv.cols - 1), 3)
        p = rest.points(k)
        cross = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        area = 0.5 * np.linalg.norm(cross, axis=1)
        assert area.sum() == pytest.approx(WIDTH * HEIGHT, rel=1e-12)
        np.testing.assert_allclose(area, 0.5 * lv.du * lv.dv, rtol=1e-12)
        normal = cross / np.linalg.norm(cross, axis=1)[:, None]
        np.testing.assert_allclose(normal @ normal[0], 1.0, rtol=0, atol=1e-12)
        # every grid edge of the triangulation is a structural edge or the "\" diagonal
        # the next level inserts points on
        for a, b in ((0, 1), (1, 2), (2, 0)):
            i, j = np.minimum(tri[:, a], tri[:, b]), np.maximum(tri[:, a], tri[:, b])
            dr, dc = j // lv.cols - i // lv.cols, j % lv.cols - i % lv.cols
            steps = set(zip(dr.tolist(), dc.tolist()))
            assert steps <= {(0, 1), (1, 0), (1, 1)}
        # every quad is split once: each (0,1)/(1,0) edge and each diagonal appears
        edges = set()
        for a, b in ((0, 1), (1, 2), (2, 0)):
            edges |= set(zip(np.minimum(tri[:, a], tri[:, b]).tolist(),
                             np.maximum(tri[:, a], tri[:, b]).tolist()))
        n_edges = (lv.rows * (lv.cols - 1) + (lv.rows - 1) * lv.cols
                   + (lv.rows - 1) * (lv.cols - 1))
        assert len(edges) == n_edges


def test_face_centre_points_lie_on_a_triangle_edge(model, rest):
    # grid_triangles splits quads along the diagonal that the next level inserts points
    # on, so each inserted point's parents form an edge of a level k-1 triangle.
    for k in range(1, LEVELS):
        lp = model.level(k - 1)
        tri = model.grid_triangles(k - 1)
        ids = model.ids_at(k - 1)
        edges = set()
        for a, b in ((0, 1), (1, 2), (2, 0)):
            ia, ib = ids[tri[:, a]], ids[tri[:, b]]
            edges |= set(zip(np.minimum(ia, ib).tolist(), np.maximum(ia, ib).tolist()))
        for pid in range(lp.point_count, model.level(k).point_count):
            p0, p1 = model.parents[pid]
            assert (min(p0, p1), max(p0, p1)) in edges


def test_representative_exists_on_every_level(model, rest):
    # representative(id, k) follows first parents down to level k: it must be an id of
    # level k, be the id itself where that exists, and lie within the anchor chain's
    # reach: each hop moves at most half a level-(j-1) diagonal, so the distance is
    # bounded by the sum of those half diagonals (plus rounding).
    finest = rest.points_by_id(model, LEVELS - 1)
    for pid in range(model.point_count):
        intro = model.intro_level[pid]
        for k in range(LEVELS):
            rep = model.representative(pid, k)
            assert 0 <= rep < model.level(k).point_count
            assert model.intro_level[rep] <= k
            if intro <= k:
                assert rep == pid
            else:
                reach = sum(0.5 * np.hypot(model.level(j - 1).du, model.level(j - 1).dv)
                            for j in range(k + 1, intro + 1))
                assert np.linalg.norm(finest[rep] - finest[pid]) <= reach + 1e-12
                # the position of the representative on its own level is the same
                assert np.array_equal(rest.position_of(model, rep, k),
                                      rest.position_of(model, rep, LEVELS - 1))


def test_prolong_reproduces_linear_fields(model, rest):
    # Midpoint interpolation reproduces any affine field exactly; the rest positions are
    # affine in (row, col), so prolonging level k gives level k+1's rest positions up to
    # rounding: a few ulp of the largest coordinate (|x| < 3 m -> 8 * eps * 3).
    for k in range(LEVELS - 1):
        out = np.full_like(rest.q[k + 1], np.nan)
        kernels.prolong(rest.q[k], out)
        np.testing.assert_allclose(out, rest.q[k + 1], rtol=0, atol=8 * EPS * 3.0)
        # inherited points are copied (bit for bit)
        assert np.array_equal(out[:, 0::2, 0::2], rest.q[k])
    # an arbitrary affine velocity field: v = A x + b
    rng = np.random.default_rng(7)
    amat, bvec = rng.normal(size=(3, 3)), rng.normal(size=3)
    for k in range(LEVELS - 1):
        vc = np.ascontiguousarray(np.einsum('ij,jrc->irc', amat, rest.q[k])
                                  + bvec[:, None, None])
        vf = np.einsum('ij,jrc->irc', amat, rest.q[k + 1]) + bvec[:, None, None]
        out = np.zeros_like(vf)
        kernels.prolong(vc, out)
        np.testing.assert_allclose(out, vf, rtol=0, atol=1e-13)


def test_prolong_matches_parents(model):
    # prolong's grid rule and model.parents describe the same edges: prolonging a
    # random coarse field gives, for every inserted id, the mean over its parents.
    rng = np.random.default_rng(3)
    for k in range(1, LEVELS):
        lp, lv = model.level(k - 1), model.level(k)
        coarse = rng.normal(size=(2, lp.rows, lp.cols))
        fine = np.zeros((2, lv.rows, lv.cols))
        kernels.prolong(coarse, fine)
        by_id_c = coarse.reshape(2, -1)[:, lp.id_to_grid]
        by_id_f = fine.reshape(2, -1)[:, lv.id_to_grid]
        assert np.array_equal(by_id_f[:, :lp.point_count], by_id_c)
        p = model.parents[lp.point_count:lv.point_count]
        expected = 0.5 * (by_id_c[:, p[:, 0]] + by_id_c[:, p[:, 1]])
        assert np.array_equal(by_id_f[:, lp.point_count:], expected)
