"""The smallest eigenpair of a symmetric 3x3 matrix in closed form, without allocation: the
kernel under PCA normals (:mod:`fourd.geometry.normals`) and the rank-2 rotations of
:mod:`fourd.geometry.rotations`.

References
----------
Smith: Eigenvalues of a symmetric 3x3 matrix, Communications of the ACM 4(4), 1961.
"""

from __future__ import annotations

import numba
import numpy as np

#: :func:`smallest_eigenpair` status: a unit eigenvector was found.
FOUND = 0
#: The matrix is (nearly) a multiple of the identity: every vector is an eigenvector.
ISOTROPIC = 1
#: The smallest eigenvalue is not distinct enough for the cross-product construction.
DEGENERATE = 2


@numba.njit(cache=True)
def smallest_eigenpair(a00, a01, a02, a11, a12, a22, tolerance):
    """Smallest eigenvalue of the symmetric matrix ``[[a00, a01, a02], [., a11, a12],
    [., ., a22]]`` and its unit eigenvector: ``(value, x, y, z, status)``.

    The eigenvalue from the trigonometric closed form; the vector as the largest cross product
    of two rows of ``A - value I``. ``status`` is :data:`FOUND`, :data:`ISOTROPIC` (the vector
    is ``(0, 0, 1)``, the value the mean eigenvalue) or :data:`DEGENERATE` (the largest cross
    product's squared length is at most ``tolerance * p2^2``, ``p2`` the squared deviation
    from isotropy; the vector is 0).
    """
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    if p2 <= 1e-300:
        return q, 0.0, 0.0, 1.0, ISOTROPIC
    pp = np.sqrt(p2 / 6.0)
    b00 = (a00 - q) / pp
    b11 = (a11 - q) / pp
    b22 = (a22 - q) / pp
    b01 = a01 / pp
    b02 = a02 / pp
    b12 = a12 / pp
    r = (
        b00 * (b11 * b22 - b12 * b12)
        - b01 * (b01 * b22 - b12 * b02)
        + b02 * (b01 * b12 - b11 * b02)
    ) / 2.0
    r = min(max(r, -1.0), 1.0)
    smallest = q + 2.0 * pp * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    m00 = a00 - smallest
    m11 = a11 - smallest
    m22 = a22 - smallest
    # rows 0 x 1, 0 x 2, 1 x 2 of A - smallest I; the longest
    c0 = a01 * a12 - a02 * m11
    c1 = a02 * a01 - m00 * a12
    c2 = m00 * m11 - a01 * a01
    best = c0 * c0 + c1 * c1 + c2 * c2
    d0 = a01 * m22 - a02 * a12
    d1 = a02 * a02 - m00 * m22
    d2 = m00 * a12 - a01 * a02
    length = d0 * d0 + d1 * d1 + d2 * d2
    if length > best:
        c0, c1, c2, best = d0, d1, d2, length
    d0 = m11 * m22 - a12 * a12
    d1 = a12 * a02 - a01 * m22
    d2 = a01 * a12 - m11 * a02
    length = d0 * d0 + d1 * d1 + d2 * d2
    if length > best:
        c0, c1, c2, best = d0, d1, d2, length
    if best <= tolerance * p2 * p2:
        return smallest, 0.0, 0.0, 0.0, DEGENERATE
    scale = 1.0 / np.sqrt(best)
    return smallest, c0 * scale, c1 * scale, c2 * scale, FOUND
