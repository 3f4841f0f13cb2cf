"""Garment folds found in a video frame (Popa's thesis, sections 4.3.1 and 4.4).

Under diffuse light on a matte fabric, a fold's ridge is bright and its valleys dark ("dark
equals deep"), so each fold component shows as a pair of roughly parallel image edges
flanking a bright or a dark band. :func:`fold_edges` finds such pairs in one image:

1. raw edges by Canny (``skimage.feature.canny``) at several filter sizes (Table 4.1's "Canny
   radii") and two image resolutions, traced into pixel chains (junctions cut);
2. each chain fitted by quadrics ``v = a u^2 + b u + c`` in its own principal frame, split
   where the fit is off by more than a pixel or bends too much (fold contours are nearly
   straight along the fold's axis);
3. oriented so that the darker side is on the left, from the brightness a few pixels to each
   side; edges with no clear darker side, or with a change of hue across them (texture, not
   shape), are dropped;
4. consecutive pieces merged where their ends meet, their orientations agree and the merge
   is still one low-curvature quadric;
5. paired: parallel (within ``max_angle_degrees``), opposite in orientation, of similar length,
   at most ``max_distance`` apart; ridge pairs (the band between them brighter) and longer
   pairs first, each edge in one pair at most. Unpaired edges are dropped.

Pairs from every filter size and resolution are pooled; where two overlap, the better one
(by the same priority) stays. Coordinates are pixels of the full-resolution image, x right, y
down.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.ndimage import convolve, map_coordinates
from scipy.spatial import cKDTree

from fourd.errors import InputError

__all__ = ["FoldEdge", "FoldEdgeOptions", "FoldPair", "fold_edges", "trace_edges"]


@dataclass(frozen=True)
class FoldEdgeOptions:
    """The fold-edge filter's parameters (thesis Table 4.1 and section 4.4); lengths in pixels
    of the full-resolution image.

    Attributes
    ----------
    canny_sigmas : tuple of float
        Gaussian widths of the Canny detector, one pass each (Table 4.1: 1, 2, 3 for most
        garments).
    canny_quantiles : (float, float)
        Canny's hysteresis thresholds as quantiles of the gradient magnitude (inside the mask):
        a fold's shading is soft, and its contrast depends on the light and the fabric, so the
        thresholds follow the image rather than fixed grey levels.
    scales : tuple of float
        Image resolutions searched (1: full).
    max_distance : float
        Largest distance between the two edges of a pair (Table 4.1: 100 pixels; inf allowed).
    max_angle_degrees : float
        Largest angle between the tangents of paired edges at their closest points (the
        thesis: 45).
    min_length : float
        Shortest edge kept.
    max_fit_error : float
        Largest distance of a chain's pixel from its quadric before the chain is split.
    max_curvature : float
        Largest curvature of a kept quadric, 1 / pixels.
    side_offset : float
        How far to each side of an edge its brightness and hue are read.
    min_contrast : float
        Smallest mean brightness difference across an edge (0-1 grey levels) for it to have
        an orientation.
    max_hue_change : float
        Largest mean change of chromaticity across an edge (texture edges change hue).
    merge_gap : float
        Ends of two edges closer than this may be merged.
    min_length_ratio : float
        The shorter edge of a pair is at least this fraction of the longer.
    """

    canny_sigmas: tuple[float, ...] = (1.0, 2.0, 3.0)
    canny_quantiles: tuple[float, float] = (0.8, 0.9)
    scales: tuple[float, ...] = (1.0, 0.5)
    max_distance: float = 100.0
    max_angle_degrees: float = 45.0
    min_length: float = 12.0
    max_fit_error: float = 1.0
    max_curvature: float = 0.05
    side_offset: float = 3.0
    min_contrast: float = 0.02
    max_hue_change: float = 0.06
    merge_gap: float = 4.0
    min_length_ratio: float = 0.4


class FoldEdge(NamedTuple):
    """An oriented fold edge: ``points [K, 2]`` (x, y pixels) in order, the darker side on the
    left of travel; ``contrast``: mean brightness difference across it."""

    points: np.ndarray
    contrast: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())


class FoldPair(NamedTuple):
    """Two fold edges flanking one fold component: ``ridge`` when the band between them is
    brighter (a ridge), ``distance`` the mean distance between them (pixels)."""

    first: FoldEdge
    second: FoldEdge
    ridge: bool
    distance: float

    @property
    def length(self) -> float:
        return self.first.length + self.second.length


# ------------------------------------------------------------------------------------------
# 1. raw edges


def trace_edges(mask: np.ndarray) -> list[np.ndarray]:
    """Pixel chains ``[K, 2]`` (x, y) of a thin binary edge map, cut at junctions (pixels with
    three or more 8-neighbours), each ordered from one end to the other."""
    from skimage.measure import label
    from skimage.morphology import thin

    # one pixel wide in the 8-connected sense: staircase corners would count as junctions
    mask = thin(np.asarray(mask, dtype=bool))
    kernel = np.ones((3, 3), dtype=np.int64)
    kernel[1, 1] = 0
    neighbours = convolve(mask.astype(np.int64), kernel, mode="constant")
    simple = mask & (neighbours <= 2)
    labels = label(simple, connectivity=2)
    chains = []
    ys, xs = np.nonzero(labels)
    order = np.argsort(labels[ys, xs], kind="stable")
    ys, xs, ids = ys[order], xs[order], labels[ys, xs][order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    ends = np.r_[starts[1:], len(ids)]
    for a, b in zip(starts, ends, strict=True):
        pixels = np.column_stack([xs[a:b], ys[a:b]])
        chains.append(_order_chain(pixels))
    return chains


def _order_chain(pixels: np.ndarray) -> np.ndarray:
    """The pixels of one simple chain in walking order (from an end, or anywhere on a loop)."""
    if len(pixels) <= 2:
        return pixels.astype(np.float64)
    tree = cKDTree(pixels)
    pairs = tree.query_pairs(1.5, output_type="ndarray")
    neighbours = [[] for _ in range(len(pixels))]
    for i, j in pairs:
        neighbours[i].append(j)
        neighbours[j].append(i)
    degree = np.array([len(n) for n in neighbours])
    start = int(np.flatnonzero(degree == 1)[0]) if (degree == 1).any() else 0
    order, seen = [start], {start}
    while True:
        nxt = [n for n in neighbours[order[-1]] if n not in seen]
        if not nxt:
            break
        order.append(nxt[0])
        seen.add(nxt[0])
    return pixels[order].astype(np.float64)


# ------------------------------------------------------------------------------------------
# 2. quadric fits


def _quadric_fit(points: np.ndarray):
    """``(max distance, max curvature)`` of the quadric through ``points [K, 2]`` in their
    principal frame."""
    centre = points.mean(axis=0)
    _, _, axes = np.linalg.svd(points - centre, full_matrices=False)
    u = (points - centre) @ axes[0]
    v = (points - centre) @ axes[1]
    design = np.column_stack([u**2, u, np.ones_like(u)])
    coefficients, *_ = np.linalg.lstsq(design, v, rcond=None)
    error = float(np.abs(design @ coefficients - v).max())
    slope = 2 * coefficients[0] * u + coefficients[1]
    curvature = float((2 * abs(coefficients[0]) / (1 + slope**2) ** 1.5).max())
    return error, curvature


def _smooth_pieces(chain: np.ndarray, options: FoldEdgeOptions) -> list[np.ndarray]:
    """The chain split until every piece is one quadric within the limits."""
    if _length(chain) < options.min_length:
        return []
    error, curvature = _quadric_fit(chain)
    if error <= options.max_fit_error and curvature <= options.max_curvature:
        return [chain]
    middle = len(chain) // 2
    return _smooth_pieces(chain[: middle + 1], options) + _smooth_pieces(chain[middle:], options)


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0


# ------------------------------------------------------------------------------------------
# 3. orientation


def _normals(points: np.ndarray) -> np.ndarray:
    """Unit left normals ``[K, 2]`` of a polyline (left of travel as the image shows it, y
    down)."""
    tangent = np.gradient(points, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
    return np.column_stack([tangent[:, 1], -tangent[:, 0]])


def _sample(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image [H, W]`` or ``[H, W, C]`` at ``points [K, 2]`` (x, y)."""
    coords = [points[:, 1], points[:, 0]]
    if image.ndim == 2:
        return map_coordinates(image, coords, order=1, mode="nearest")
    return np.stack([map_coordinates(image[..., c], coords, order=1, mode="nearest") for c in range(image.shape[2])], 1)


def _oriented(points, grey, chroma, options: FoldEdgeOptions) -> FoldEdge | None:
    normal = _normals(points)
    left = points + options.side_offset * normal
    right = points - options.side_offset * normal
    difference = float(np.mean(_sample(grey, right) - _sample(grey, left)))  # > 0: left darker
    if abs(difference) < options.min_contrast:
        return None
    if chroma is not None:
        hue = np.linalg.norm(_sample(chroma, left) - _sample(chroma, right), axis=1).mean()
        if hue > options.max_hue_change:
            return None
    if difference < 0:
        points = points[::-1]
    return FoldEdge(points, abs(difference))


# ------------------------------------------------------------------------------------------
# 4. merging and 5. pairing


def _merged(edges: list[FoldEdge], options: FoldEdgeOptions) -> list[FoldEdge]:
    """Edges joined end to start where they meet, agree in orientation and still fit one
    quadric."""
    edges = list(edges)
    changed = True
    while changed and len(edges) > 1:
        changed = False
        heads = np.array([e.points[0] for e in edges])
        tails = np.array([e.points[-1] for e in edges])
        gap = np.linalg.norm(tails[:, None, :] - heads[None, :, :], axis=2)
        np.fill_diagonal(gap, np.inf)
        for i, j in zip(*np.nonzero(gap <= options.merge_gap), strict=True):
            joined = np.concatenate([edges[i].points, edges[j].points])
            error, curvature = _quadric_fit(joined)
            if error <= options.max_fit_error and curvature <= options.max_curvature:
                contrast = 0.5 * (edges[i].contrast + edges[j].contrast)
                edges = [e for k, e in enumerate(edges) if k not in (i, j)] + [FoldEdge(joined, contrast)]
                changed = True
                break
    return edges


def _pair_candidates(edges: list[FoldEdge], options: FoldEdgeOptions) -> list[FoldPair]:
    pairs = []
    dense = [_densify(e.points) for e in edges]
    trees = [cKDTree(d) for d in dense]
    tangents = [np.gradient(d, axis=0) for d in dense]
    cosine_limit = np.cos(np.radians(options.max_angle_degrees))
    for a in range(len(edges)):
        for b in range(a + 1, len(edges)):
            la, lb = edges[a].length, edges[b].length
            if min(la, lb) < options.min_length_ratio * max(la, lb):
                continue
            distance, nearest = trees[b].query(dense[a])
            if distance.max() > options.max_distance:
                continue
            # most of a faces b (not only its end)
            facing = (nearest > 0) & (nearest < len(dense[b]) - 1)
            if facing.mean() < 0.5:
                continue
            ta = tangents[a] / np.maximum(np.linalg.norm(tangents[a], axis=1, keepdims=True), 1e-300)
            tb = tangents[b][nearest]
            tb = tb / np.maximum(np.linalg.norm(tb, axis=1, keepdims=True), 1e-300)
            cosine = np.einsum("ij,ij->i", ta, tb)[facing]
            if np.median(cosine) > -cosine_limit:  # opposite orientation and parallel
                continue
            # the band between them: on a's right (brighter side) for a ridge
            middle = 0.5 * (dense[a][facing] + dense[b][nearest[facing]])
            side = np.einsum("ij,ij->i", middle - dense[a][facing], _normals(dense[a])[facing])
            ridge = bool(np.median(side) < 0)
            pairs.append(FoldPair(edges[a], edges[b], ridge, float(distance[facing].mean())))
    return pairs


def _densify(points: np.ndarray, step: float = 1.0) -> np.ndarray:
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    at = np.linspace(0.0, length[-1], max(2, int(np.ceil(length[-1] / step)) + 1))
    return np.column_stack([np.interp(at, length, points[:, k]) for k in range(2)])


def _priority(pair: FoldPair):
    return (not pair.ridge, -pair.length)


def _select(pairs: list[FoldPair]) -> list[FoldPair]:
    """Each edge in one pair at most, by priority (ridges, then longer)."""
    chosen, used = [], set()
    for pair in sorted(pairs, key=_priority):
        keys = (id(pair.first), id(pair.second))
        if used.isdisjoint(keys):
            chosen.append(pair)
            used.update(keys)
    return chosen


def _overlap(p: FoldPair, q: FoldPair, tolerance: float = 3.0) -> bool:
    mine = np.concatenate([_densify(p.first.points), _densify(p.second.points)])
    theirs = cKDTree(np.concatenate([_densify(q.first.points), _densify(q.second.points)]))
    return bool(np.mean(theirs.query(mine)[0] <= tolerance) > 0.5)


# ------------------------------------------------------------------------------------------


def fold_edges(image: np.ndarray, options: FoldEdgeOptions | None = None, *, mask: np.ndarray | None = None) -> list[FoldPair]:
    """The fold-edge pairs of one video frame (see the module docstring).

    Parameters
    ----------
    image : array [H, W] (grey) or [H, W, 3] (RGB), uint8 or floats in [0, 1]
    mask : bool array [H, W], optional
        Where the garment is (edges elsewhere are dropped, as the thesis drops edges that do
        not project onto the garment).
    """
    from skimage.feature import canny
    from skimage.transform import rescale

    options = options or FoldEdgeOptions()
    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.shape[0] < 8 or image.shape[1] < 8:
        raise InputError(f"a video frame must be an image [H, W] or [H, W, 3], got shape {list(image.shape)}")
    rgb = image.astype(np.float64) / (255.0 if image.dtype == np.uint8 else 1.0)
    grey = rgb if rgb.ndim == 2 else rgb[..., :3].mean(axis=2)
    chroma = None
    if rgb.ndim == 3:
        chroma = rgb[..., :3] / np.maximum(rgb[..., :3].sum(axis=2, keepdims=True), 1e-6)
    pooled: list[FoldPair] = []
    for scale in options.scales:
        small = grey if scale == 1.0 else rescale(grey, scale, anti_aliasing=True)
        small_chroma = None if chroma is None else (
            chroma if scale == 1.0 else rescale(chroma, scale, anti_aliasing=True, channel_axis=2))
        small_mask = None if mask is None else (
            mask if scale == 1.0 else rescale(mask.astype(float), scale) > 0.5)
        scaled = FoldEdgeOptions(**{**options.__dict__, **{
            "max_distance": options.max_distance * scale, "min_length": options.min_length * scale,
            "merge_gap": max(2.0, options.merge_gap * scale), "side_offset": max(1.5, options.side_offset * scale)}})
        for sigma in options.canny_sigmas:
            edges_map = canny(small, sigma=sigma, mask=small_mask, low_threshold=options.canny_quantiles[0],
                              high_threshold=options.canny_quantiles[1], use_quantiles=True)
            edges = []
            for chain in trace_edges(edges_map):
                for piece in _smooth_pieces(chain, scaled):
                    oriented = _oriented(piece, small, small_chroma, scaled)
                    if oriented is not None:
                        edges.append(oriented)
            edges = _merged(edges, scaled)
            for pair in _select(_pair_candidates(edges, scaled)):
                pooled.append(FoldPair(
                    FoldEdge(pair.first.points / scale, pair.first.contrast),
                    FoldEdge(pair.second.points / scale, pair.second.contrast),
                    pair.ridge, pair.distance / scale))
    kept: list[FoldPair] = []
    for pair in sorted(pooled, key=_priority):
        if not any(_overlap(pair, other) for other in kept):
            kept.append(pair)
    return kept
