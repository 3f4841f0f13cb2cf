"""Material-aware mesh deformation and stiffness learned from motion (Popa 2009, thesis
``004_f87f5acf96d50b57.txt``, chapter 2 and Appendix A).

A :class:`Material` holds bending stiffness per interior edge and shearing stiffness per face;
a :class:`Deformer` precomputes a mesh, its material and its anchor triangles once and then
poses it from anchor transformations or dragged vertices; :func:`learn_material` learns the
material from example poses (the frames of a reconstruction).
"""

from fourd.deform.algebra import Similarity, blend, similarity_matrices, split_similarity
from fourd.deform.deformer import Deformer, rotation_about
from fourd.deform.extrapolation import blending_weights
from fourd.deform.frames import deformation_gradients, local_frames
from fourd.deform.learning import learn_material
from fourd.deform.material import (
    Material,
    from_shearing,
    load_material,
    save_material,
    uniform_material,
)
from fourd.deform.reposition import Repositioning

__all__ = [
    "Deformer",
    "Material",
    "Repositioning",
    "Similarity",
    "blend",
    "blending_weights",
    "deformation_gradients",
    "from_shearing",
    "learn_material",
    "load_material",
    "local_frames",
    "rotation_about",
    "save_material",
    "similarity_matrices",
    "split_similarity",
    "uniform_material",
]
