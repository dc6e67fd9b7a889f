"""The object's boundary in its own frame B: a convex polygon (numpy only).

The object is any convex polygon; the paper's box is the default (`ConvexPolygon.box`).
Vertices run counter-clockwise about the area centroid, the origin of B. Arclength s runs
counter-clockwise along the boundary from vertex 0, the start of the "right" face (the
edge whose outward normal points closest to +x; for the box the corner (+w/2, -h/2): up
the right face (length h), left along the top (w), down the left face (h), right along the
bottom (w)). Every function takes s modulo the perimeter.

A contact frame at s is (n_B, t_B): the outward unit normal of the face and the
counter-clockwise unit tangent t_B = z x n_B.

The box keeps its closed forms (distance, nearest point, inertia): the generic polygon
formulas agree with them to rounding (tests check it), and the closed forms keep the
box's plans identical to the last bit across this generalization.
"""

from __future__ import annotations

import functools

import numpy as np

SMOOTH_EDGE = 0.01  # m, the longest edge of a polygonized disc or ellipse: tan(alpha / 2) keeps it a face
# rad, vertices turning less are no corner for a rolling fingertip: a 1 cm sphere pivoting over one shifts its
# contact by at most r alpha = 2.6 mm, within the 5 mm the 15 mm corner margin leaves spare at a right angle
SMOOTH_VERTEX_ANGLE = np.radians(15.0)


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def polygon_problem(points) -> str | None:
    """Why `points` (V, 2), a vertex sequence in either orientation, is not a convex polygon
    (None when it is one). O(V): a closed polygon is convex and simple exactly when it turns the
    same way at every vertex and its turns add up to one full turn (its turning number is +-1);
    a self-intersecting one turns by another multiple of 2 pi (a bow tie 0, a pentagram 4 pi)."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 2:
        return f"vertices must be (x, y) pairs, got an array of shape {p.shape}"
    if len(p) < 3:
        return f"a polygon needs at least 3 vertices, got {len(p)}"
    if not np.all(np.isfinite(p)):
        return "vertices must be finite numbers"
    n = len(p)
    edges = np.roll(p, -1, axis=0) - p  # edge i runs from vertex i to vertex i + 1
    repeated = np.flatnonzero(np.all(edges == 0, axis=1))
    if repeated.size:
        i = int(repeated[0])
        j = (i + 1) % n
        i, j = min(i, j), max(i, j)
        return f"vertices {i} and {j} repeat the point ({p[i][0]:g}, {p[i][1]:g})"
    following = np.roll(edges, -1, axis=0)
    turns = _cross(edges, following)  # at vertex i + 1
    scale = np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)) ** 2
    flat = np.abs(turns) <= 1e-12 * scale
    if np.any(flat):
        k = (int(np.flatnonzero(flat)[0]) + 1) % n
        return f"vertex {k} ({p[k][0]:g}, {p[k][1]:g}) is collinear with its neighbours; leave it out"
    turning = np.sum(np.arctan2(turns, np.einsum("va,va->v", edges, following)))  # rad, each turn within +-pi
    windings = int(round(abs(turning) / (2 * np.pi)))
    if windings != 1:
        return (
            f"the polygon is self-intersecting (its edges turn by {np.degrees(turning):.0f} deg in all, a simple "
            "polygon's by +-360)"
        )
    if not (np.all(turns > 0) or np.all(turns < 0)):
        k = (int(np.flatnonzero(np.sign(turns) != np.sign(turning))[0]) + 1) % n
        return f"the polygon is not convex (it turns the other way at vertex {k}, ({p[k][0]:g}, {p[k][1]:g}))"
    return None


class ConvexPolygon:
    """A convex polygon in B: vertices (V, 2) counter-clockwise about the origin, vertex 0 the
    start of the right face. Build it with `box` or `from_points`."""

    def __init__(self, vertices, box_half: tuple[float, float] | None = None, smooth: bool = False):
        v = np.array(vertices, dtype=float)
        self.vertices = v  # (V, 2) m
        self.box_half = box_half  # (w/2, h/2) m of the box (its closed forms), else None
        # a polygonized smooth outline (a disc, an ellipse): contact normals are the smooth curve's
        # (interpolated between vertex normals), so no grasp leans on the facets' tilted normals
        self.smooth = smooth
        d = np.roll(v, -1, axis=0) - v
        self.edge_lengths = np.linalg.norm(d, axis=1)  # (V,) m
        self.directions = d / self.edge_lengths[:, None]  # (V, 2) counter-clockwise unit tangents
        self.normals = np.stack([self.directions[:, 1], -self.directions[:, 0]], axis=1) + 0.0  # outward (no -0.0)
        self.offsets = np.einsum("fa,fa->f", self.normals, v)  # (V,) m, face f: n_f . p = offset_f
        self._corners = np.concatenate([[0.0], np.cumsum(self.edge_lengths)[:-1]])
        self.perimeter = float(np.sum(self.edge_lengths))
        if box_half:  # the box's sums in their own order
            w, h = 2 * box_half[0], 2 * box_half[1]
            self._corners, self.perimeter = np.array([0.0, h, h + w, 2 * h + w]), 2.0 * (w + h)
        cross = _cross(v, np.roll(v, -1, axis=0))
        self.area = float(cross.sum() / 2)  # m^2
        nxt = np.roll(v, -1, axis=0)
        polar = float(
            np.sum(
                cross
                * (
                    v[:, 0] ** 2
                    + v[:, 0] * nxt[:, 0]
                    + nxt[:, 0] ** 2
                    + v[:, 1] ** 2
                    + v[:, 1] * nxt[:, 1]
                    + nxt[:, 1] ** 2
                )
            )
            / 12
        )
        # 12 x the polar second moment per unit area (m^2): inertia = mass * this / 12.
        self._inertia_sum = (box_half[0] * 2) ** 2 + (box_half[1] * 2) ** 2 if box_half else 12 * polar / self.area

    @classmethod
    def box(cls, width: float, height: float) -> ConvexPolygon:
        a, b = width / 2, height / 2
        return cls([[a, -b], [a, b], [-a, b], [-a, -b]], box_half=(a, b))

    @classmethod
    def from_points(cls, points, smooth: bool = False) -> ConvexPolygon:
        """The polygon through `points` (V, 2) m, a vertex sequence in either orientation:
        made counter-clockwise, moved so that its area centroid is the origin, and started at
        its right face. `smooth`: the points sample a smooth convex curve (see __init__).
        Raises ValueError naming the problem (polygon_problem)."""
        problem = polygon_problem(points)
        if problem:
            raise ValueError(problem)
        p = np.array(points, dtype=float)
        if np.sum(_cross(p, np.roll(p, -1, axis=0))) < 0:
            p = p[::-1]
        cross = _cross(p, np.roll(p, -1, axis=0))
        centroid = np.sum((p + np.roll(p, -1, axis=0)) * cross[:, None], axis=0) / (3 * cross.sum())
        p = p - centroid + 0.0
        d = np.roll(p, -1, axis=0) - p
        angles = np.arctan2(-d[:, 0], d[:, 1])  # outward normal angle of each face
        start = min(range(len(p)), key=lambda f: (round(abs(angles[f]), 12), angles[f]))
        p = np.roll(p, -start, axis=0)
        half = np.abs(p[0])
        corners = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]]) * half
        if np.array_equal(p, corners) and not smooth:
            return cls(p, box_half=(float(half[0]), float(half[1])))
        return cls(p, smooth=smooth)

    @property
    def is_box(self) -> bool:
        return self.box_half is not None

    @functools.cached_property
    def back_offsets(self) -> np.ndarray:
        """(V,) m, min_j n_f . v_j: where the polygon ends along each face's normal n_f, opposite
        that face (it spans [back_offsets_f, offsets_f] along n_f). O(V log V): the vertex farthest
        along -n_f is the one between the two faces whose normal angles bracket n_f's plus pi (the
        normals of a counter-clockwise convex polygon turn counter-clockwise, once round)."""
        angles = np.unwrap(np.arctan2(self.normals[:, 1], self.normals[:, 0]))  # (V,) rad, increasing
        opposite = angles[0] + np.mod(angles + np.pi - angles[0], 2 * np.pi)
        far = np.searchsorted(angles, opposite) % len(angles)  # vertex j joins faces j - 1 and j
        return np.einsum("fa,fa->f", self.normals, self.vertices[far])

    @property
    def circumradius(self) -> float:
        """m, the largest distance from the centroid to a vertex (the box: its half diagonal)."""
        if self.box_half:
            return float(np.hypot(*self.box_half))
        return float(np.max(np.linalg.norm(self.vertices, axis=1)))

    def inertia(self, mass: float) -> float:
        """kg m^2, the moment of inertia about z through the centroid of a uniform plate of `mass` kg."""
        return mass * self._inertia_sum / 12.0

    def second_moments(self) -> tuple[float, float, float]:
        """(Sxx, Syy, Sxy) m^2: (1/A) int x^2, y^2 and x y dA over the polygon, about its centroid."""
        v = self.vertices
        x0, y0 = v[:, 0], v[:, 1]
        x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
        cross = x0 * y1 - x1 * y0
        area = cross.sum() / 2
        Sxx = np.sum(cross * (x0 * x0 + x0 * x1 + x1 * x1)) / 12 / area
        Syy = np.sum(cross * (y0 * y0 + y0 * y1 + y1 * y1)) / 12 / area
        Sxy = np.sum(cross * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0)) / 24 / area
        return float(Sxx), float(Syy), float(Sxy)

    def corner_arclengths(self) -> np.ndarray:
        """Arclengths (V,) of the vertices (for the box 0, h, h + w, 2h + w)."""
        return self._corners.copy()

    def point(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Contact point p_BC and outward unit normal n_B at arclength s."""
        s = float(s) % self.perimeter
        for f in range(len(self.vertices)):
            if s <= self.edge_lengths[f]:
                return self.vertices[f] + s * self.directions[f], self._normal(f, s)
            s -= self.edge_lengths[f]
        f = len(self.vertices) - 1
        return self.vertices[f] + self.edge_lengths[f] * self.directions[f], self._normal(f, self.edge_lengths[f])

    def points(self, arclengths) -> tuple[np.ndarray, np.ndarray]:
        """(p_BC (k, 2), n_B (k, 2)) for an array of arclengths (vectorized `point`)."""
        s = np.mod(np.asarray(arclengths, dtype=float), self.perimeter)
        face = np.clip(np.searchsorted(self._corners, s, side="left") - 1, 0, len(self._corners) - 1)
        along = s - self._corners[face]
        return self.vertices[face] + along[:, None] * self.directions[face], self._normals_on(face, along)

    def _normal(self, face: int, along: float) -> np.ndarray:
        return self._normals_on(np.array([face]), np.array([along]))[0]

    def _normals_on(self, face: np.ndarray, along: np.ndarray) -> np.ndarray:
        """Outward unit normals at `along` m into faces `face`: the face's, or on a smooth outline the
        vertex normals (bisectors) interpolated linearly along the face."""
        if not self.smooth:
            return self.normals[face].copy()
        bisectors = self.normals + np.roll(self.normals, 1, axis=0)  # vertex f joins faces f - 1 and f
        bisectors /= np.linalg.norm(bisectors, axis=1, keepdims=True)
        u = (along / self.edge_lengths[face])[:, None]
        n = (1 - u) * bisectors[face] + u * bisectors[(face + 1) % len(self.vertices)]
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def tangent(self, s: float) -> np.ndarray:
        """Counter-clockwise unit tangent t_B = z x n_B at arclength s."""
        _, n = self.point(s)
        return np.array([-n[1], n[0]])

    def arclength(self, p_B) -> float:
        """Arclength of the boundary point nearest to p_B."""
        p = self.project(p_B)
        s0, best, best_s = 0.0, np.inf, 0.0
        for start, direction, length in zip(self.vertices, self.directions, self.edge_lengths):
            t = np.clip(np.dot(p - start, direction), 0.0, length)
            d = np.linalg.norm(start + t * direction - p)
            if d < best - 1e-15:
                best, best_s = d, s0 + t
            s0 += length
        return float(best_s % self.perimeter)

    def project(self, p_B) -> np.ndarray:
        """The boundary point nearest to p_B."""
        p = np.asarray(p_B, dtype=float)
        if not self.box_half:
            return self.nearest_points(p)
        a, b = self.box_half
        if abs(p[0]) <= a and abs(p[1]) <= b:  # inside: push out through the nearest face
            gaps = np.array([a - p[0], b - p[1], a + p[0], b + p[1]])
            k = int(np.argmin(gaps))
            q = p.copy()
            q[k % 2] = (a, b, -a, -b)[k]
            return q
        return np.array([np.clip(p[0], -a, a), np.clip(p[1], -b, b)])

    def corner_distance(self, s: float) -> float:
        """Arclength distance from s to the nearest corner."""
        s = float(s) % self.perimeter
        d = np.abs(self._corners - s)
        return float(np.min(np.minimum(d, self.perimeter - d)))

    @property
    def exterior_angles(self) -> np.ndarray:
        """(V,) rad, how far the boundary turns at each vertex (pi/2 for the box's corners)."""
        incoming = np.roll(self.directions, 1, axis=0)
        return np.arctan2(_cross(incoming, self.directions), np.einsum("va,va->v", incoming, self.directions))

    def corner_margins(self, margin: float) -> np.ndarray:
        """(V,) m, the arclength kept free of contacts on each side of each vertex: `margin` scaled
        by tan(alpha / 2) for an exterior angle alpha, at most `margin`.

        A fingertip sphere of radius r on a face touches only that face while it stays at least
        r tan(alpha / 2) from the vertex, so a blunt corner needs less room than a right angle
        (tan(pi / 4) = 1: the box keeps the full margin) and a vertex barely bent is a face; sharper
        corners keep `margin`, which is never smaller than at a right angle."""
        return margin * np.minimum(1.0, np.round(np.tan(self.exterior_angles / 2), 12))  # round: the box's 1 exactly

    def sides(self, arclengths) -> np.ndarray:
        """(k,) the side each arclength lies on: a run of faces joined by vertices that turn less
        than SMOOTH_VERTEX_ANGLE (a polygonized disc is one side; the box has four, its faces).
        A fingertip rolls across such a vertex as across a face: it pivots by the small angle."""
        corners = self._corners[self.exterior_angles >= SMOOTH_VERTEX_ANGLE]
        s = np.mod(np.asarray(arclengths, dtype=float), self.perimeter)
        return np.searchsorted(corners, s, side="right") % max(len(corners), 1)

    def corner_free(self, arclengths, margin: float) -> np.ndarray:
        """(k,) bool, whether each arclength keeps corner_margins(margin) from every vertex."""
        return np.all(self._vertex_gaps(arclengths) >= self.corner_margins(margin), axis=-1)

    def clear_of_sides_ends(self, arclengths, gap: float) -> np.ndarray:
        """(k,) bool, whether each arclength keeps `gap` m from every vertex that ends a side (one a
        rolling fingertip pivots over: it turns SMOOTH_VERTEX_ANGLE or more; see `sides`)."""
        ends = self.exterior_angles >= SMOOTH_VERTEX_ANGLE
        return np.all(self._vertex_gaps(arclengths)[..., ends] >= gap, axis=-1)

    def _vertex_gaps(self, arclengths) -> np.ndarray:
        """(k, V) m, the arclength from each of `arclengths` to each vertex, either way round."""
        s = np.mod(np.asarray(arclengths, dtype=float), self.perimeter)
        gap = np.abs(s[..., None] - self._corners)
        return np.minimum(gap, self.perimeter - gap)

    def signed_distance(self, p_B) -> float:
        """Exact signed distance from p_B to the polygon (negative inside)."""
        p = np.asarray(p_B, dtype=float)
        if not self.box_half:
            return float(self.signed_distances(p))
        q = np.abs(p) - np.array(self.box_half)
        return float(np.linalg.norm(np.maximum(q, 0.0)) + min(max(q[0], q[1]), 0.0))

    # ---- vectorized over points (..., 2) ---------------------------------------------------

    def _segment_parameters(self, p_B: np.ndarray) -> np.ndarray:
        """(..., V): each point's position along each face, clipped to the face."""
        rel = p_B[..., None, :] - self.vertices
        return np.clip(np.einsum("...fa,fa->...f", rel, self.directions), 0.0, self.edge_lengths)

    def signed_distances(self, p_B: np.ndarray) -> np.ndarray:
        """Exact signed distance (...,) of points p_B (..., 2) to the polygon (negative inside)."""
        p_B = np.asarray(p_B, dtype=float)
        if self.box_half:
            q = np.abs(p_B) - np.array(self.box_half)
            return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
        faces = p_B @ self.normals.T - self.offsets  # (..., V)
        t = self._segment_parameters(p_B)
        nearest = self.vertices + t[..., None] * self.directions  # (..., V, 2)
        outside = np.linalg.norm(p_B[..., None, :] - nearest, axis=-1).min(axis=-1)
        inside = faces.max(axis=-1)
        return np.where(inside > 0, outside, inside)

    def nearest_points(self, p_B: np.ndarray) -> np.ndarray:
        """The boundary point (..., 2) nearest to each p_B (..., 2), in B."""
        p_B = np.asarray(p_B, dtype=float)
        if self.box_half:
            half = np.array(self.box_half)
            clipped = np.clip(p_B, -half, half)
            inside = np.all(np.abs(p_B) < half, axis=-1)
            # Inside: out through the nearest face, along the axis with the smallest gap to its face.
            axis = np.argmin(half - np.abs(p_B), axis=-1)
            sign = np.where(p_B >= 0, 1.0, -1.0)
            pushed = np.where(np.arange(2) == axis[..., None], sign * half, p_B)
            return np.where(inside[..., None], pushed, clipped)
        t = self._segment_parameters(p_B)
        candidates = self.vertices + t[..., None] * self.directions  # (..., V, 2)
        k = np.argmin(np.linalg.norm(p_B[..., None, :] - candidates, axis=-1), axis=-1)
        return np.take_along_axis(candidates, k[..., None, None], axis=-2)[..., 0, :]

    def face_normals(self, p_BC: np.ndarray) -> np.ndarray:
        """Outward unit normals (..., 2) of the faces nearest to boundary points p_BC (..., 2)."""
        p = np.asarray(p_BC, dtype=float)
        if self.box_half:
            on_side = np.abs(np.abs(p[..., 0]) - self.box_half[0]) <= np.abs(np.abs(p[..., 1]) - self.box_half[1])
            n = np.zeros_like(p)
            n[..., 0] = np.where(on_side, np.sign(p[..., 0]), 0.0)
            n[..., 1] = np.where(on_side, 0.0, np.sign(p[..., 1]))
            return n
        face = np.argmax(p @ self.normals.T - self.offsets, axis=-1)
        if not self.smooth:
            return self.normals[face]
        along = np.clip(np.einsum("...a,...a->...", p - self.vertices[face], self.directions[face]), 0.0, None)
        flat_face, flat_along = np.ravel(face), np.ravel(np.minimum(along, self.edge_lengths[face]))
        return self._normals_on(flat_face, flat_along).reshape(p.shape)

    def penetration_depths(self, corners: np.ndarray) -> np.ndarray:
        """How deep convex polygons (..., m, 2: their corners in B, in order) overlap this one:
        the least translation that separates them, by separating axes (the faces' normals of
        both), 0 where they do not overlap. (...,) m."""
        c = np.asarray(corners, dtype=float)
        edges = np.roll(c, -1, axis=-2) - c
        their_normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)
        their_normals /= np.linalg.norm(their_normals, axis=-1, keepdims=True)
        axes = np.concatenate(
            [np.broadcast_to(self.normals, (*c.shape[:-2], *self.normals.shape)), their_normals], axis=-2
        )  # (..., V + m, 2)
        mine = np.einsum("...ad,vd->...av", axes, self.vertices)  # (..., axes, V)
        theirs = np.einsum("...ad,...md->...am", axes, c)  # (..., axes, m)
        overlap = np.minimum(mine.max(-1) - theirs.min(-1), theirs.max(-1) - mine.min(-1))
        return np.maximum(overlap.min(-1), 0.0)

    def __repr__(self) -> str:
        return f"ConvexPolygon({np.round(self.vertices, 6).tolist()})"


def wrap_angle(a):
    """An angle (rad, or an array of them) in [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def rotation_2d(theta: float) -> np.ndarray:
    """R_WB for a rotation by theta about z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def box_to_world(pose, p_B) -> np.ndarray:
    """p_W of a point p_B given the object pose (x, y, theta)."""
    return np.asarray(pose[:2], dtype=float) + rotation_2d(pose[2]) @ np.asarray(p_B, dtype=float)


def world_to_box(pose, p_W) -> np.ndarray:
    """p_B of a point p_W given the object pose (x, y, theta)."""
    return rotation_2d(pose[2]).T @ (np.asarray(p_W, dtype=float) - np.asarray(pose[:2], dtype=float))


# ---- vectorized, for whole trajectories (physics check, execution schedule) ----------------


def rotations_2d(theta: np.ndarray) -> np.ndarray:
    """R_WB (K, 2, 2) for rotations by theta (K,) about z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def poses_world_to_box(x: np.ndarray, p_W: np.ndarray) -> np.ndarray:
    """p_B (K, P, 2) of world points p_W (K, P, 2) at object poses x (K, 3)."""
    return np.einsum("kba,kpb->kpa", rotations_2d(x[:, 2]), p_W - x[:, None, :2])


def poses_box_to_world(x: np.ndarray, p_B: np.ndarray) -> np.ndarray:
    """p_W (K, P, 2) of box points p_B (K, P, 2) at object poses x (K, 3)."""
    return x[:, None, :2] + np.einsum("kab,kpb->kpa", rotations_2d(x[:, 2]), p_B)


def ellipse_points(semi_x: float, semi_y: float, max_edge: float = SMOOTH_EDGE) -> np.ndarray:
    """(V, 2) vertices of a convex polygon inscribed in the ellipse with semi-axes `semi_x`, `semi_y`
    (m; equal: a disc), V a multiple of 4 with every edge at most `max_edge`, and a face centred on
    each axis (as the box's faces are), so the shape keeps the ellipse's symmetries."""
    radius = max(semi_x, semi_y)  # an ellipse's chords are at most those of its larger axis' circle
    n = 4 * int(np.ceil(np.pi / (4 * np.arcsin(min(1.0, max_edge / (2 * radius))))))
    angles = 2 * np.pi * (np.arange(n) + 0.5) / n
    return np.stack([semi_x * np.cos(angles), semi_y * np.sin(angles)], axis=1)


# -- the box in space ------------------------------------------------------------------------
# Its faces by outward normal in B, in this order (the index names a face everywhere in space).
BOX_FACE_NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
BOX_FACE_NAMES = ("+x", "-x", "+y", "-y", "+z", "-z")


def box_face_grid(half, per_side: int = 3, inset: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """(p_BC (6, per_side^2, 3), n_B (6, 3)): contacts on each face of a box of half-sizes `half`
    (3,) m, on a per_side x per_side grid `inset` m in from the face's edges (a fingertip sphere
    of that radius touches that face alone), faces in BOX_FACE_NORMALS order."""
    half = np.asarray(half, dtype=float)
    grid = []
    for n in BOX_FACE_NORMALS:
        axis = int(np.argmax(np.abs(n)))
        u, v = [k for k in range(3) if k != axis]
        su, sv = (np.linspace(-1, 1, per_side) * max(half[k] - inset, 0.0) for k in (u, v))
        points = np.zeros((per_side, per_side, 3))
        points[..., axis] = n[axis] * half[axis]
        points[..., u], points[..., v] = np.meshgrid(su, sv, indexing="ij")
        grid.append(points.reshape(-1, 3))
    return np.array(grid), BOX_FACE_NORMALS.copy()


def quaternion_angle(q0, q1) -> float:
    """rad in [0, pi], the angle of the rotation from unit quaternion q0 to q1 ([w, x, y, z])."""
    return float(2 * np.arccos(min(1.0, abs(float(np.dot(q0, q1))))))


def quaternion_slerp(q0, q1, t) -> np.ndarray:
    """(len(t), 4) unit quaternions [w, x, y, z] on the geodesic from q0 to q1 at fractions t (the
    shorter way: q1 and -q1 are one rotation)."""
    q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    t = np.asarray(t, dtype=float)[:, None]
    omega = np.arccos(min(1.0, float(np.dot(q0, q1))))
    if omega < 1e-12:
        return np.tile(q0, (len(t), 1))
    out = (np.sin((1 - t) * omega) * q0 + np.sin(t * omega) * q1) / np.sin(omega)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


# -- rotations and the box's distance in space -----------------------------------------------------
def quaternion_matrices(quats) -> np.ndarray:
    """(..., 3, 3) rotation matrices of the quaternions (..., 4) [w, x, y, z] (normalized here)."""
    q = np.asarray(quats, dtype=float)
    w, x, y, z = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_quaternions(R) -> np.ndarray:
    """(..., 4) unit quaternions [w, x, y, z] with w >= 0 of the rotation matrices R (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    phi = so3_log(R)
    angle = np.linalg.norm(phi, axis=-1, keepdims=True)
    axis = np.divide(phi, angle, out=np.zeros_like(phi), where=angle > 0)
    return np.concatenate([np.cos(angle / 2), np.sin(angle / 2) * axis], axis=-1)


def quaternion_product(q0, q1) -> np.ndarray:
    """(4,) the quaternion q0 q1 ([w, x, y, z]): the rotation q1, then q0."""
    w0, v0 = q0[0], np.asarray(q0[1:], dtype=float)
    w1, v1 = q1[0], np.asarray(q1[1:], dtype=float)
    return np.concatenate([[w0 * w1 - v0 @ v1], w0 * v1 + w1 * v0 + np.cross(v0, v1)])


def quaternion_error_W(q_ref, q) -> np.ndarray:
    """(3,) rad, in W: the rotation vector e that turns orientation q onto q_ref, R_ref = exp([e]x) R (unit
    quaternions [w, x, y, z]), from the log map of R_ref^T R (the shorter way: q and -q are one rotation)."""
    q_ref = np.asarray(q_ref, dtype=float)
    d = quaternion_product(np.concatenate([q_ref[:1], -q_ref[1:]]), q)  # R_ref^T R
    d = -d if d[0] < 0 else d
    s = np.linalg.norm(d[1:])
    phi = d[1:] * (2 * np.arctan2(s, d[0]) / s if s > 1e-12 else 2.0)  # log(R_ref^T R), in the reference's frame
    return -quaternion_matrices(q_ref) @ phi


def skew(v) -> np.ndarray:
    """(..., 3, 3) [v]x, the matrix of v x (.) for vectors v (..., 3)."""
    v = np.asarray(v)
    zero = np.zeros_like(v[..., 0])
    return np.stack(
        [
            np.stack([zero, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], zero, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], zero], axis=-1),
        ],
        axis=-2,
    )


def so3_exp(phi) -> np.ndarray:
    """(..., 3, 3) exp([phi]x), the rotation by |phi| rad about phi (..., 3) (Rodrigues; series below 1e-6 rad)."""
    phi = np.asarray(phi, dtype=float)
    theta2 = np.sum(phi * phi, axis=-1)[..., None, None]
    small = theta2 < 1e-12
    theta = np.sqrt(np.where(small, 1.0, theta2))
    a = np.where(small, 1.0 - theta2 / 6, np.sin(theta) / theta)
    b = np.where(small, 0.5 - theta2 / 24, (1 - np.cos(theta)) / np.where(small, 1.0, theta2))
    K = skew(phi)
    return np.eye(3) + a * K + b * (K @ K)


def so3_log(R) -> np.ndarray:
    """(..., 3) the rotation vector phi (|phi| in [0, pi]) with exp([phi]x) = R (..., 3, 3)."""
    R = np.asarray(R, dtype=float)
    vee = 0.5 * np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.linalg.norm(vee, axis=-1)
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1)
    theta = np.arctan2(s, c)
    scale = np.where(s > 1e-9, theta / np.where(s > 1e-9, s, 1.0), 1.0 + theta**2 / 6)
    phi = vee * scale[..., None]
    # Near pi the antisymmetric part vanishes: the axis from the symmetric part's largest column.
    near_pi = c < -0.99
    if np.any(near_pi):
        Rn = R[near_pi]
        B = (Rn + np.swapaxes(Rn, -1, -2)) / 2 - c[near_pi][:, None, None] * np.eye(3)  # (1 - c) a a^T
        column = np.take_along_axis(B, np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)[:, None, None], -1)
        axis = column[..., 0] / np.linalg.norm(column[..., 0], axis=-1, keepdims=True)
        axis *= np.where(np.sum(axis * vee[near_pi], axis=-1, keepdims=True) < 0, -1.0, 1.0)
        phi[near_pi] = axis * theta[near_pi][..., None]
    return phi


def rotation_angles(R) -> np.ndarray:
    """(...) rad in [0, pi], the angles of the rotation matrices R (..., 3, 3)."""
    return np.linalg.norm(so3_log(R), axis=-1)


def box_signed_distances(half, p_B) -> np.ndarray:
    """(...) m, the signed distance of points p_B (..., 3, in B) from the box of half-sizes `half`
    (3,) centred at B's origin: positive outside, negative inside (exact)."""
    d = np.abs(np.asarray(p_B, dtype=float)) - np.asarray(half, dtype=float)
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
    return outside + np.minimum(d.max(axis=-1), 0.0)


def box_signed_distance_gradient(half, p_B) -> np.ndarray:
    """(..., 3) the gradient of box_signed_distances at p_B (..., 3): outside the unit vector from the nearest
    box point, inside the deepest face's normal."""
    sign = np.where(p_B < 0, -1.0, 1.0)
    d = np.abs(p_B) - half
    out = np.maximum(d, 0.0)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    face = np.eye(3)[np.argmax(d, axis=-1)]
    return np.where(norm > 0, out / np.where(norm > 0, norm, 1.0), face) * sign


def box_face_normals(half, p_B) -> np.ndarray:
    """(..., 3) the outward unit normal in B of the box face nearest each point p_B (..., 3)."""
    p = np.asarray(p_B, dtype=float)
    axis = np.argmax(np.abs(p) - np.asarray(half, dtype=float), axis=-1)
    n = np.zeros_like(p)
    np.put_along_axis(n, axis[..., None], np.where(np.take_along_axis(p, axis[..., None], -1) < 0, -1.0, 1.0), -1)
    return n


def box_outward_directions(half, p_B) -> np.ndarray:
    """(..., 3) unit vectors in B that carry points p_B (..., 3) away from the box of half-sizes `half` (3,)
    centred at B's origin: from the nearest surface point through the point where it lies outside, the outward
    normal of the nearest face where it lies inside or on the surface."""
    p = np.asarray(p_B, dtype=float)
    outside = p - np.clip(p, -np.asarray(half, dtype=float), np.asarray(half, dtype=float))
    length = np.linalg.norm(outside, axis=-1, keepdims=True)
    return np.where(length > 1e-12, outside / np.maximum(length, 1e-12), box_face_normals(half, p))


def segment_box_nearest(half, a_B, b_B, iterations: int = 60) -> np.ndarray:
    """(...) in [0, 1]: the fraction t along the segments a_B -> b_B (..., 3, in B) of their point of least
    signed distance from the box (half-sizes `half`), by a golden-section search, the
    ends included."""
    a, b = np.asarray(a_B, dtype=float), np.asarray(b_B, dtype=float)
    ratio = (np.sqrt(5.0) - 1) / 2
    lo, hi = np.zeros(a.shape[:-1]), np.ones(a.shape[:-1])

    def at(t):
        return box_signed_distances(half, a + t[..., None] * (b - a))

    for _ in range(iterations):
        t1, t2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        left = at(t1) <= at(t2)
        lo, hi = np.where(left, lo, t1), np.where(left, t2, hi)
    candidates = np.stack([(lo + hi) / 2, np.zeros_like(lo), np.ones_like(lo)], -1)
    values = np.stack([at(candidates[..., i]) for i in range(3)], -1)
    return np.take_along_axis(candidates, np.argmin(values, axis=-1)[..., None], -1)[..., 0]


def segment_box_distances(half, a_B, b_B, iterations: int = 60) -> np.ndarray:
    """(...) m, the least signed distance from the box (half-sizes `half`) of the points on the
    segments a_B -> b_B (..., 3, in B): the distance at segment_box_nearest's point. The signed distance
    from a convex set is convex along a segment, so a golden-section search finds its least value (to
    0.618^iterations of the length)."""
    a, b = np.asarray(a_B, dtype=float), np.asarray(b_B, dtype=float)
    t = segment_box_nearest(half, a, b, iterations)
    return box_signed_distances(half, a + t[..., None] * (b - a))


def segment_segment_nearest(a0, a1, b0, b1) -> tuple[np.ndarray, np.ndarray]:
    """(s (...), t (...)) in [0, 1]: the fractions along the segments a0 -> a1 and b0 -> b1 (..., 3) of a pair
    of their nearest points, in closed form (Ericson, Real-Time Collision Detection 5.1.9); a segment whose
    ends coincide is a point (its fraction 0), parallel segments get s = 0 and its nearest t."""
    a0, a1, b0, b1 = (np.asarray(v, dtype=float) for v in (a0, a1, b0, b1))
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a, e = np.sum(d1 * d1, -1), np.sum(d2 * d2, -1)
    b, c, f = np.sum(d1 * d2, -1), np.sum(d1 * r, -1), np.sum(d2 * r, -1)
    eps = 1e-18  # m^2: a segment shorter than 1 nm is a point

    def ratio(num, den):
        return np.clip(np.divide(num, den, out=np.zeros_like(num), where=den > eps), 0.0, 1.0)

    denom = a * e - b * b  # >= 0, 0 for parallel segments
    s = ratio(b * f - c * e, np.where(denom > eps * a * e, denom, 0.0))
    s = np.where(e > eps, s, ratio(-c, a))  # b a point: a's point nearest it
    t_free = np.divide(b * s + f, e, out=np.zeros_like(s), where=e > eps)
    s = np.where(t_free < 0.0, ratio(-c, a), np.where(t_free > 1.0, ratio(b - c, a), s))
    return s, np.clip(t_free, 0.0, 1.0)


def capsule_distances(a0, a1, radius_a, b0, b1, radius_b) -> np.ndarray:
    """(...) m, the signed distances between capsules (axis a0 -> a1 (..., 3) of radius radius_a, axis b0 -> b1
    of radius radius_b): their axes' least distance less both radii (negative: how deep they overlap)."""
    s, t = segment_segment_nearest(a0, a1, b0, b1)
    gap = (a0 + s[..., None] * (a1 - a0)) - (b0 + t[..., None] * (b1 - b0))
    return np.linalg.norm(gap, axis=-1) - radius_a - radius_b
