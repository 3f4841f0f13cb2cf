"""Method ``kinematic``: a 4D implicit surface (4D MPU over a hextree), the urshape extracted
at the first time, and the urshape slid along the space-time surface as rigidly as possible.

Pipeline (000_00387fefe94cc850.txt):

1. space-time point cloud (section 2, :mod:`.frames`): per-frame outlier removal (beyond the paper: points
   whose mean distance to their neighbours is far above the typical one), per-frame normals
   (given, or PCA oriented by the sensors or by propagation), 4D points ``(x, y, z, w)`` with
   ``w = delta * (t - t0) / dt`` (``dt`` the median frame step) and 4D normals ``(n, 0)``;
   ``delta`` is the median nearest-neighbour spacing of the first frame (the paper takes the
   median edge length of a triangulation of the first frame, which estimates the same
   sampling distance), times ``time_scale`` (default 2; the paper uses 1, see Options);
2. 4D MPU (section 3, :mod:`.mpu4d`; its kernels in :mod:`.mpu_fit`, :mod:`.mpu_tree`,
   :mod:`.mpu_eval`), over all frames or over sliding windows of frames (:mod:`.field`);
3. urshape (section 4, :mod:`.urshape`);
4. sliding (section 5, :mod:`.sliding`, with :mod:`.rigid`, :mod:`.projection` and
   :mod:`.arap_solve`), optionally with sub-steps in time (:mod:`.animate`,
   :mod:`.trajectories`);
5. output at the input times or at any requested ``times``.

Whole captures (issue 56): :func:`reconstruct_streamed` (:mod:`.stream`, ``fourd reconstruct
--stream``) runs the same steps window by window on frames read when needed and writes the
result frame by frame, so memory is bounded by the window, not the capture's length.

Beyond the paper (all documented options): robust MPU error / normal-spread quantile,
rigid point-to-plane prediction of the initial guess, constraint linearised at the guess,
time sub-steps, sliding windows of frames for the 4D fit, every second point in the 4D fit
(``fit_stride``), ``time_scale`` 2, the data term and temporal smoothing; frames sparser
than the template densified first (``densify``: each frame meshed on its own and its surface
sampled at the template's resolution; the whole crane capture at 2,641 points per frame
0.0232 / 0.0208 -> 0.0097 / 0.0099, correspondence mean / last frame).

Known limit of the paper's sliding: motion between frames much larger than the features
(crane's kicking leg, up to 14% of the diagonal per kept frame) leaves no space-time surface
connecting the frames, and the projection of 5.1 loses that limb. With ``large_motion``
(default) such frames are first registered to their own points by as-rigid-as-possible ICP
(:mod:`.register`); crane correspondence 0.027 / 0.046 -> 0.011 / 0.015 (mean / last frame).

Measured limit of the implicit itself, and the data term that removes it (rigid-turn, standard
scans): registering the *true* shape rigidly to ``f(., t) = 0`` frame by frame leaves pose
errors of 0.005-0.013 of the diagonal (about 2 degrees at the first frame, 3 at the last, near
0 in the middle: the fit blends neighbouring frames and is one-sided at the ends), while
point-to-plane ICP of the same shape to the raw points of each frame is at 0.001. Giving the
4D normals a time component did not change this, nor did an ICP guess against the raw points
while constraint (2) tied the vertices back to ``f``. So with ``data_term`` (default) the
urshape is projected onto the first frame's own points and, at every input time, the observed
vertices are registered (one rigid motion, iterated), projected and constrained against that
frame's IMLS surface (:mod:`.framesurface`), the 4D implicit filling in where the frame has no
points. Measured: rigid-turn correspondence 0.029 / 0.058 (mean / last frame) -> 0.0017 /
0.0026; the price is each frame's own scan noise, taken out by one temporal smoothing pass.
Local rigid patches are not used against the data: on the turning blob they let the surface
slide (0.026 with 800-vertex patches against 0.002 without).

Public functions reused by other methods: :func:`extract_template` and :func:`slide`
(both take any :class:`fourd.geometry.field.Field4D`).
"""

from fourd.methods.kinematic.animate import animate
from fourd.methods.kinematic.arap import arap_energy
from fourd.methods.kinematic.arap_solve import slide_precompute
from fourd.methods.kinematic.field import SpaceTimeField, space_time_points
from fourd.methods.kinematic.frames import prepare_frames
from fourd.methods.kinematic.framesurface import FrameSurface
from fourd.methods.kinematic.mpu4d import MPU4D, MPUOptions, fit_mpu4d
from fourd.methods.kinematic.options import COMMON_OPTIONS, MIN_FRAMES, RESULT, Options
from fourd.methods.kinematic.pipeline import reconstruct
from fourd.methods.kinematic.projection import project_to_surface
from fourd.methods.kinematic.sliding import SlideOptions, slide
from fourd.methods.kinematic.stream import StreamSummary, reconstruct_streamed
from fourd.methods.kinematic.trajectories import smooth_trajectories
from fourd.methods.kinematic.urshape import extract_template, template_cell_size

__all__ = [
    "COMMON_OPTIONS",
    "MIN_FRAMES",
    "RESULT",
    "Options",
    "reconstruct",
    "reconstruct_streamed",
    "StreamSummary",
    "animate",
    "extract_template",
    "slide",
    "SlideOptions",
    "project_to_surface",
    "arap_energy",
    "slide_precompute",
    "fit_mpu4d",
    "MPUOptions",
    "MPU4D",
    "SpaceTimeField",
    "space_time_points",
    "prepare_frames",
    "template_cell_size",
    "FrameSurface",
    "smooth_trajectories",
]
