"""Method ``learned``: ``kinematic`` tracking twice, the second time with the stiffness the first
one's motion teaches.

The sliding of ``kinematic`` (Süßmuth et al. 2008, ``000_00387fefe94cc850.txt``, section 5)
keeps the template as rigid as possible with the same cotangent weight on every edge, but real
skin bends, stretches and twists more at the joints than along the bones. Here the first
tracking's frames are example poses for the material learning of Popa's thesis
(``004_f87f5acf96d50b57.txt``, section 2.7, :func:`fourd.deform.learn_material`): every
interior edge gets a bending stiffness in ``[epsilon, 1 + epsilon]``, small where the first
tracking bent the surface across it. The second tracking multiplies each edge's ARAP weight by
that stiffness (:attr:`~fourd.methods.kinematic.sliding.SlideOptions.edge_stiffness`), so the
template bends where the object bent and stays stiff elsewhere. The urshape is the same in both
passes (same data, options and seed).

Beyond both papers; the issue asked for it to become the default only where it helps.
"""

from __future__ import annotations

import dataclasses
import logging

from fourd.animation import AnimatedMesh
from fourd.deform import learn_material
from fourd.errors import InputError
from fourd.geometry.meshes import face_adjacency
from fourd.methods import kinematic
from fourd.sequence import PointCloudSequence

log = logging.getLogger("fourd.methods.learned")

MIN_FRAMES = kinematic.MIN_FRAMES
RESULT = AnimatedMesh
#: The options ``fourd options learned`` shows first.
COMMON_OPTIONS = ("stiffness_floor", *kinematic.COMMON_OPTIONS)

__all__ = ["COMMON_OPTIONS", "MIN_FRAMES", "Options", "RESULT", "reconstruct"]


@dataclasses.dataclass(frozen=True)
class Options(kinematic.Options):
    """The ``kinematic`` method's options (both passes use them), and:

    Attributes
    ----------
    stiffness_floor : float
        The smallest learned stiffness (``epsilon`` of the learning, 0.05): the weight of the
        edge that bent most in the first pass, against about 1 for one that did not.
    """

    stiffness_floor: float = 0.05

    def __post_init__(self):
        super().__post_init__()
        if not 0 < self.stiffness_floor <= 1:
            raise ValueError(f"stiffness_floor must be in (0, 1], got {self.stiffness_floor}")


def reconstruct(seq: PointCloudSequence, options: Options | None = None) -> AnimatedMesh:
    """Track with ``kinematic``, learn the stiffness from its frames, track again with it."""
    options = Options() if options is None else options
    base = kinematic.Options(**{f.name: getattr(options, f.name) for f in dataclasses.fields(kinematic.Options)})
    # the second tracking's stiffness is per edge of the urshape as the sliding has it
    first = kinematic.reconstruct(seq, base, split_pinched=False)
    material = learn_material(first.rest, first.vertices, first.faces, epsilon=options.stiffness_floor)
    _, edges = face_adjacency(first.faces)
    log.info(
        "learned: bending stiffness from the first tracking, %.0f%% of the edges below 0.5",
        100 * float((material.bending < 0.5).mean()),
    )
    second = kinematic.reconstruct(seq, base, edge_stiffness=(edges, material.bending))
    if len(second.faces) != len(first.faces):
        raise InputError("the second tracking's template differs from the first's")  # pragma: no cover
    return second
