"""An animated mesh closed at the end: its small holes filled by the membrane of thesis 3.6.2
(004, :mod:`.hole_filling`), and its small handles opened and closed the same way (topological
noise). Used by ``assembly`` and ``surfels`` on their results.

Each step is found in the first frame and then applied to every frame, so one connectivity serves
the whole sequence:

1. fragments are dropped (:func:`~fourd.geometry.fans.fragments`): a flap of a few faces
   hanging from the surface by a vertex (at most a hundredth of the piece it touches), whose
   loop of 3 sides would be capped into a pillow, and a crumb of a few faces on its own (at
   most a thousandth of the largest piece);
2. the small holes (:func:`~fourd.geometry.hole_filling.small_holes`) are filled by the
   membrane (:func:`~fourd.geometry.hole_filling.fill_holes`), and then doubled layers are
   dropped (:func:`~fourd.geometry.doubled_layers.doubled_layers`): a small piece (a sliver,
   a bubble) lying within two edges of the closed surface, which adds nothing the surface
   lacks. It is sought after the membranes because a sliver the meshing's clipping cut off
   lies over the hole it left; a small piece the membranes closed into a pillow counts too;
3. with ``handle_hops``, the small handles of the closed mesh are cut out
   (:func:`~fourd.geometry.handles.open_small_handles`: balls of that many edges that are not
   disks) and their openings filled the same way, for a few rounds. The first frame's mesh
   gives the whole animation its connectivity, and a per-frame surface perforates the gap
   between two sheets of skin a few spacings apart into a web of tunnels (crane's first frame:
   genus 0-22 with the scan's noise, ``experiments/assembly_handles.py``);
4. in each frame, the vertices no face uses any more are dropped and every membrane vertex is
   placed by the membrane over that frame's rim, unobserved (:meth:`HoleClosing.apply`);
5. a vertex where two fans of faces touch (a pinch: two pieces meeting at a point, a rim
   crossing itself) is split into one copy per fan, at the same place
   (:func:`~fourd.geometry.fans.split_pinches`), so the result is a manifold.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np

from fourd.errors import InputError
from fourd.geometry.boundary_loops import boundary_edges, boundary_loops
from fourd.geometry.doubled_layers import doubled_layers
from fourd.geometry.fans import fragments, split_pinches
from fourd.geometry.handles import capped_genus, open_small_handles
from fourd.geometry.hole_filling import fill_holes, membrane_positions, small_holes

__all__ = ["HANDLE_ROUNDS", "HoleClosing", "close_small_holes", "holes_to_close"]

log = logging.getLogger("fourd.geometry.hole_closing")

#: Rounds of handle opening, each with balls one edge wider than the last: cutting a handle out
#: can leave a neighbour that no ball could hold beside the cut until the opening was filled
#: (crane's first 4 frames: genus 22 -> 4 in one round of 4 edges, 3 over rounds of 4, 5 and 6;
#: dfaust-hopping 2 -> 1 and 0; benchmarks/METHODS.md).
HANDLE_ROUNDS = 3


class HoleClosing(NamedTuple):
    """The membranes of :func:`close_small_holes`, made in the first frame, to place in every
    frame: the closed mesh's ``faces``, its ``vertices`` in the first frame (the original ones
    kept first, then the membranes'), the ``filled [N']`` membrane vertices, the ``holes``'
    rims, the C1 weight ``smoothness`` and the original vertices ``kept [K]`` (None: all; the
    others were inside a handle cut out). With pinches, ``split_faces`` are the faces given to
    the result and ``copies [N' + P]`` the vertex of ``vertices`` each of its vertices copies."""

    faces: np.ndarray
    vertices: np.ndarray
    filled: np.ndarray
    holes: list
    smoothness: float
    kept: np.ndarray | None = None
    split_faces: np.ndarray | None = None
    copies: np.ndarray | None = None

    @property
    def output_faces(self) -> np.ndarray:
        """The result's faces: ``faces`` with the pinches split."""
        return self.faces if self.split_faces is None else self.split_faces

    @property
    def output_count(self) -> int:
        """The result's vertex count."""
        return len(self.vertices) if self.copies is None else len(self.copies)

    def apply(self, vertices: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(faces, vertices [T, N', 3], observed [T, N'])``: the mesh at ``vertices [T, N, 3]``
        (any frames of the mesh the holes were found in; ``observed [T, N]``) with the holes
        closed, the membranes placed in each frame from that frame's rim, unobserved."""
        if self.kept is not None:
            vertices, observed = vertices[:, self.kept], observed[:, self.kept]
        frames, count = vertices.shape[:2]
        added = len(self.vertices) - count
        vertices = np.concatenate([vertices, np.repeat(self.vertices[None, count:], frames, axis=0)], axis=1)
        vertices = membrane_positions(vertices, self.faces, self.filled, self.holes, smooth=self.smoothness)
        observed = np.concatenate([observed, np.zeros((frames, added), dtype=bool)], axis=1)
        if self.copies is not None:
            return self.split_faces, vertices[:, self.copies], observed[:, self.copies]
        return self.faces, vertices, observed


def holes_to_close(first: np.ndarray, faces: np.ndarray, max_fraction: float, smoothness: float = 1.0,
                   handle_hops: int = 0) -> HoleClosing | None:
    """The membranes closing the holes of the mesh ``faces`` at its first frame's positions
    ``first [N, 3]`` (:func:`close_small_holes`), after its small handles are opened when
    ``handle_hops`` > 0, and its pinches split (the module docstring); None when there is
    nothing to do."""
    count = len(first)
    vertices, faces = np.asarray(first, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    original = faces
    dropped = fragments(faces, count)
    if dropped.any():
        log.info("dropped %d faces of fragments (flaps hanging by a vertex, crumbs)", int(dropped.sum()))
        faces = faces[~dropped]
    filled_holes: list = []
    holes = small_holes(vertices, faces, max_fraction=max_fraction) if max_fraction > 0 else []
    # a degenerate rim (InputError) leaves that step undone, not the steps before or after it
    if holes:
        try:
            closed = fill_holes(vertices, faces, holes=holes, area_matched=True, smooth=smoothness)
            # the membrane may add no vertex: a small hole closed by its rim's triangles
            log.info("closing %d holes with %d membrane vertices", len(holes), len(closed.vertices) - count)
            vertices, faces, filled_holes = closed.vertices, closed.faces, list(closed.holes)
        except InputError as error:
            log.warning("holes left open: %s", error)
    # against the closed surface: a sliver the clipping cut off lies over the hole it left
    doubled = doubled_layers(vertices, faces)
    if doubled.any():
        log.info("dropped %d faces of doubled layers (small pieces along the closed surface)", int(doubled.sum()))
        faces = faces[~doubled]
    if handle_hops > 0:
        try:
            vertices, faces, opened = _open_handles(vertices, faces, smoothness, handle_hops)
            filled_holes += opened
        except InputError as error:
            log.warning("small handles left: %s", error)
    closing = _closing(count, original, vertices, faces, filled_holes, smoothness)
    if len(vertices) == count and not filled_holes and not dropped.any() and not doubled.any() and closing.copies is None:
        return None
    return closing


def _open_handles(vertices: np.ndarray, faces: np.ndarray, smoothness: float, hops: int):
    """``(vertices, faces, holes)``: the mesh with its small handles cut out and the openings
    filled, for up to :data:`HANDLE_ROUNDS` rounds of balls of ``hops``, ``hops + 1``, ...
    edges (vertices of cut faces stay, unused)."""
    genus = capped_genus(faces, len(vertices))
    filled_holes, cuts = [], 0
    for round_ in range(HANDLE_ROUNDS):
        keep = open_small_handles(vertices, faces, hops=hops + round_)
        if keep.all():
            continue
        rim_before = np.zeros(len(vertices), dtype=bool)
        rim_before[boundary_edges(faces, len(vertices)).ravel()] = True
        faces = faces[keep]
        # the openings: the loops that no boundary loop of the mesh before had a vertex of
        openings = [loop for loop in boundary_loops(faces, len(vertices)) if not rim_before[loop].any()]
        closed = fill_holes(vertices, faces, holes=openings, area_matched=True, smooth=smoothness)
        vertices, faces = closed.vertices, closed.faces
        filled_holes += list(closed.holes)
        cuts += int((~keep).sum())
    if cuts:
        log.info("opened small handles: %d faces cut out, genus %d -> %d", cuts, genus,
                 capped_genus(faces, len(vertices)))
    return vertices, faces, filled_holes


def _closing(count: int, original: np.ndarray, vertices: np.ndarray, faces: np.ndarray, holes: list,
             smoothness: float) -> HoleClosing:
    """The :class:`HoleClosing` of the closed mesh ``(vertices, faces)`` whose first ``count``
    vertices are the original ones (their faces ``original``): those a cut-out handle took
    every face of are dropped, as are membrane vertices of a cut-out handle; ``holes``
    renumbered to match; the pinches of the result split."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    used_before = np.zeros(count, dtype=bool)
    used_before[original.ravel()] = True
    kept = np.flatnonzero(used[:count] | ~used_before)
    order = np.concatenate([kept, count + np.flatnonzero(used[count:])])
    number = np.full(len(vertices), -1, dtype=np.int64)
    number[order] = np.arange(len(order))
    holes = [number[hole][number[hole] >= 0] for hole in holes]
    filled = np.zeros(len(order), dtype=bool)
    filled[len(kept):] = True
    faces = number[faces]
    split, copies = split_pinches(faces, len(order))
    if len(copies) > len(order):
        log.info("split %d pinched vertices", len(copies) - len(order))
    else:
        split, copies = None, None
    return HoleClosing(faces, vertices[order], filled, [h for h in holes if len(h)], smoothness,
                       None if len(kept) == count else kept, split, copies)


def close_small_holes(faces: np.ndarray, vertices: np.ndarray, observed: np.ndarray, max_fraction: float,
                      smoothness: float = 1.0, handle_hops: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(faces, vertices, observed)``: the mesh ``faces`` at ``vertices [T, N, 3]``
    (``observed [T, N]``) with its holes of flat area at most ``max_fraction`` of their piece's
    area (:func:`~fourd.geometry.hole_filling.small_holes`, in the first frame) filled by the
    membrane of 3.6.2 (``smoothness``: weight of its C1 terms, 1 the thesis' membrane, 0 the
    flat one), and its small handles opened and filled the same way when ``handle_hops`` > 0:
    the disks triangulated in the first frame, their vertices placed in every frame by the
    membrane over that frame's rim, ``observed`` False. Unchanged (the same arrays) when there
    is nothing to close."""
    closing = holes_to_close(vertices[0], faces, max_fraction, smoothness, handle_hops)
    return (faces, vertices, observed) if closing is None else closing.apply(vertices, observed)
