"""Options of the ``garment`` method."""

from __future__ import annotations

from dataclasses import dataclass

from fourd.animation import AnimatedMesh

__all__ = ["COMMON_OPTIONS", "MIN_FRAMES", "Options", "RESULT"]

#: A sequence method: one template through the frames.
MIN_FRAMES = 2
RESULT = AnimatedMesh
#: The options users change first (``fourd options garment``).
COMMON_OPTIONS = ("photo", "boundaries", "time_sigma")


@dataclass(frozen=True)
class Options:
    """Options of the garment capture (Popa's thesis, chapter 3).

    Attributes
    ----------
    photo : str
        A photo of the garment laid out flat (white on black) with its calibration beside it
        (``pattern.json`` in the photo's folder: ``pixels_per_unit``, ``origin``, ``openings``;
        the files ``fourd synth tshirt`` writes): the template is inflated from it (3.7).
        Empty: the template is the first frame's own surface, its holes but the openings filled
        by a smooth membrane.
    boundaries : int
        How many openings the garment has (a T-shirt 4: neck, sleeves, waist; a skirt 2). 0:
        the first frame's boundary loops at least a third as long as its longest.
    keyframes : str
        A JSON file of boundary points a user picked in some frames, for sequences where the
        automatic boundary tracking loses an opening (Appendix B.2): a list ``keyframes`` of
        entries ``{"frame": 12, "points": [[x, y, z], [x, y, z], [x, y, z]]}`` with at least
        six points along one opening each; each becomes that frame's ellipse of the opening
        nearest it. Empty: automatic tracking only.
    template_edge : float
        Edge length of a template inflated from the photo, in the photo's units (0: a 60th of
        the garment's diagonal in the photo, 0.026 for the synthetic T-shirt).
    iterations : int
        As-rigid-as-possible fitting iterations per frame (three times as many in the first).
    motion_prediction : float
        Each frame's fit starts from the last frame's result moved on by this fraction of the
        last step's motion (1: constant velocity; 0: where the last frame left it). The fit
        slides to a nearby equilibrium, so its start decides which one on a fast limb.
    data_weight : float
        Weight of the closest-point data in the fit, in units of a vertex's stiffness.
    boundary_weight : float
        Weight of the openings pulled onto the frame's tracked openings, same units.
    anchor_weight : float
        Weight of the video's anchors (where the optical flow says a vertex went), same units.
        The colour guide pulls as strongly. The anchors go from frame to frame, so their errors
        add up: a light pull keeps what they see that the geometry cannot (a dress's twirl)
        without most of their drift.
    video_anchors : bool
        With multi-view video, track anchors by optical flow (:func:`fourd.appearance.anchors`,
        thesis 5.4.1) and pull the template along them; silent without video.
    color_guide : bool
        With coloured points, after each frame's fit a per-vertex Lucas-Kanade on the frame's
        colours against the first frame's (:mod:`fourd.appearance.color_guide`) says where each
        vertex went along the surface, and the fit runs again pulled there (as strongly as the
        video's anchors); silent without colours.
    template_scale : float
        Without a photo: the first frame's template surface is meshed on a grid this many
        times coarser than the frames' surfaces (the fit's cost grows with its size).
    time_sigma : float
        Gaussian smoothing of the vertex trajectories in time, frames (the thesis smooths the
        sequence in time at the end of 3.7; 0: none, measured better here, METHODS.md).
    observed_distance : float
        A vertex counts as observed in a frame when it lies within this many of the frame
        mesh's median edges of it; elsewhere the template completed it.
    wrinkles : bool
        With multi-view video, wrinkle the captured garment where the video shows folds
        (thesis chapter 4, :mod:`fourd.methods.garment.wrinkling`): for plain fabric under
        diffuse light, where a fold's valley is darker than its ridge; silent without video.
    wrinkles_hold_data : bool
        With ``wrinkles``: an observed vertex is moved by them only along its frame's data
        normal toward the data, never off it nor along it (where the scan resolves a fold, the
        scan's fold stands); the vertices the template completed take the video's folds whole.
        Off: the thesis' wrinkling everywhere.
    scheduler : str
        Where the frames' own surfaces are made (``fourd reconstruct --scheduler``): ``sync``
        here, ``processes`` side by side in local processes, or a ``dask.distributed``
        scheduler's address (``tcp://HOST:PORT``); the same surfaces either way
        (:func:`fourd.pipeline.map_frames`).
    cache_dir : str or None
        Folder keeping each frame's surface as it is made; a rerun after an interruption
        reuses them (``fourd reconstruct --cache``).
    """

    photo: str = ""
    boundaries: int = 0
    keyframes: str = ""
    template_edge: float = 0.0
    iterations: int = 10
    motion_prediction: float = 1.0
    data_weight: float = 0.5
    boundary_weight: float = 4.0
    anchor_weight: float = 0.2
    video_anchors: bool = True
    color_guide: bool = True
    template_scale: float = 2.5
    time_sigma: float = 0.0
    observed_distance: float = 2.0
    wrinkles: bool = False
    wrinkles_hold_data: bool = True
    scheduler: str = "sync"
    cache_dir: str | None = None
