"""Where along the surface each vertex's colour went: Lucas-Kanade on a frame's coloured points.

Geometry says how far a vertex is from the surface but not where along it the skin sits; the
colour it had when the template was made does (the photometric term of coloured ICP, Park, Zhou
and Koltun, ICCV 2017, made per vertex). For every vertex ``i`` at its tracked position, its
patch (the template vertices ``j`` within ``radius``) carries the reference colours ``c_j`` the
vertices had in the template's frame; the frame's colour field
(:class:`~fourd.appearance.surface_color.ColorField`) is read at the patch moved by one shift
``delta_i`` in the tangent plane, and ``delta_i`` minimises

    sum_j w_ij | C(p_j + delta_i) - c_j - b_i |^2       (per channel, Gaussian weights w_ij)

with ``b_i`` a per-channel brightness offset of the patch (log colour: a change of exposure or a
shading error the lighting fit left), by Gauss-Newton steps (Lucas and Kanade 1981, on the
surface). Against the template's colours, not the previous frame's, the errors do not add up
from frame to frame.

The shift's uncertainty (standard deviation along its worst direction, from the residual and
the patch's structure tensor, less the part of the tensor the colour noise alone makes) says
where the colour pins the vertex down: a patch of uniform colour or one stripe gives a large
(or infinite) uncertainty in at least one direction.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

__all__ = ["NOISE_MARGIN", "PhotometricShift", "photometric_shift"]

#: The structure tensor's smallest eigenvalue must exceed this many times the energy the colour
#: noise alone puts in one tangent direction (its expectation from the colour fit's residuals)
#: before the patch's shift means anything. Measured on a plane with 1% colour noise (patches of
#: about 24 vertices, 3 channels), share of vertices with an uncertainty under 1% of the plane's
#: size, printed / uniform colour: margin 0: 100% / 100%; 1: 96% / 9%; 1.5: 79% / 0%.
NOISE_MARGIN = 1.5


class PhotometricShift(NamedTuple):
    """Result of :func:`photometric_shift`.

    shift : float64 [N, 3]
        Tangential move of each vertex that best matches its patch's reference colours.
    uncertainty : float64 [N]
        Standard deviation of the shift along its least-determined tangent direction (input
        units; inf where the patch had too few neighbours).
    residual : float64 [N]
        Root mean square colour residual of the patch after the shift (log units).
    """

    shift: np.ndarray
    uncertainty: np.ndarray
    residual: np.ndarray


def photometric_shift(
    positions: np.ndarray,
    normals: np.ndarray,
    reference: np.ndarray,
    field,
    *,
    radius: float,
    neighbours: int = 24,
    iterations: int = 3,
    max_shift: float | None = None,
    brightness: str = "chroma",
) -> PhotometricShift:
    """Per-vertex tangential shift from the colours of a frame's points.

    Parameters
    ----------
    positions : float64 [N, 3]
        Tracked vertex positions in the frame.
    normals : float64 [N, 3]
        Unit normals there (the shift is kept in their tangent planes).
    reference : float64 [N, C]
        Log colours of the vertices in the template's frame (``field.sample`` of that frame).
    field : ColorField
        The frame's colour field.
    radius : float
        Patch radius (input units); weights ``exp(-d^2 / (radius / 2)^2)``.
    neighbours : int
        At most this many template vertices per patch.
    iterations : int
        Gauss-Newton steps.
    max_shift : float, optional
        Largest total shift (default ``radius``); a vertex that wants more keeps its shift
        there and gets an infinite uncertainty.
    brightness : "chroma", "shared", "channel" or "none"
        The brightness offset: one per sample common to its channels ("chroma": only the hue
        counts, so white light's shading, which moves with the lamps and not with the skin,
        cannot pass for motion), one per patch for all channels ("shared": a change of white
        light over the whole patch), one per patch and channel, or none. A patch over which the
        colour changes linearly cannot tell a shift from an offset of its own channel, so
        "channel" leaves such patches (smooth skin) without information.
    """
    positions = np.asarray(positions, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if brightness not in ("chroma", "shared", "channel", "none"):
        raise ValueError(f"brightness must be chroma, shared, channel or none, got {brightness!r}")
    n = len(positions)
    max_shift = radius if max_shift is None else max_shift
    k = min(neighbours, n)
    distance, patch = cKDTree(positions).query(positions, k=k, distance_upper_bound=radius, workers=-1)
    valid = np.isfinite(distance)
    rows = np.repeat(np.arange(n), valid.sum(axis=1))
    weights = np.exp(-((distance[valid] / (0.5 * radius)) ** 2))
    patches = sparse.csr_matrix((weights, (rows, patch[valid])), shape=(n, n))
    total = np.asarray(patches.sum(axis=1)).ravel()
    tangent = np.eye(3)[None] - normals[:, :, None] * normals[:, None, :]  # [N, 3, 3]
    shift = np.zeros((n, 3))
    for _ in range(iterations):
        system, right, _, _ = _normal_equations(
            patches, total, positions, shift, reference, field, tangent, brightness
        )
        scale = np.trace(system, axis1=1, axis2=2)
        system = system + (normals[:, :, None] * normals[:, None, :]) * (scale + 1e-9)[:, None, None]
        system += 1e-9 * np.eye(3)[None]
        step = np.linalg.solve(system, right[:, :, None])[:, :, 0]
        shift = np.einsum("nij,nj->ni", tangent, step)
        length = np.linalg.norm(shift, axis=1)
        over = length > max_shift
        shift[over] *= (max_shift / length[over])[:, None]
    system, right, residual, noise_energy = _normal_equations(
        patches, total, positions, shift, reference, field, tangent, brightness
    )
    # smallest eigenvalue of the tangential structure tensor (the normal's is zero), less what
    # the noise puts there: noise alone has a structure tensor too, whose shifts mean nothing
    eig = np.linalg.eigvalsh(system)[:, 1] - NOISE_MARGIN * noise_energy
    uncertainty = np.sqrt(residual**2 / np.maximum(eig, 1e-300))
    few = valid.sum(axis=1) < 4
    uncertainty[few | (np.linalg.norm(shift, axis=1) >= max_shift * (1 - 1e-9))] = np.inf
    return PhotometricShift(shift, uncertainty, residual)


def _normal_equations(patches, total, positions, shift, reference, field, tangent, brightness):
    """The Gauss-Newton system for every vertex's whole shift: each neighbour ``j`` is read at
    its own shifted position and continued linearly back to ``shift = 0`` (``r_j - g_j . shift_j``),
    so that the patch of ``i`` sees ``r'_j + g_j . shift_i``: ``(system [N, 3, 3], right [N, 3],
    rms residual at the current shifts [N])``, the brightness offset eliminated (the patch's
    weighted mean, over the channels too when shared)."""
    values, grads, noise = field.sample(positions + shift, with_gradients=True)  # [N, C], [N, C, 3], [N, C]
    r = values - reference
    if brightness in ("shared", "chroma"):
        residual = r - r.mean(axis=1, keepdims=True)
    elif brightness == "channel":
        residual = r - (patches @ r) / total[:, None]
    else:
        residual = r
    residual = np.sqrt((patches @ (residual**2).sum(axis=1)) / np.maximum(total * r.shape[1], 1e-300))
    r = r - (grads @ shift[:, :, None])[:, :, 0]
    if brightness == "chroma":
        # every sample's own offset common to the channels: white light's shading, whatever
        # the lamps, is such an offset in log colour; what is left is the colour's hue
        r = r - r.mean(axis=1, keepdims=True)
        grads = grads - grads.mean(axis=1, keepdims=True)
        noise = noise * (1.0 - 1.0 / r.shape[1])
    n, channels = r.shape
    gg = patches @ (grads.transpose(0, 2, 1) @ grads).reshape(n, 9)
    gr = patches @ (grads.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0]
    gg, count = gg.reshape(n, 3, 3), total * channels
    if brightness == "shared":
        mean_g = (patches @ grads.sum(axis=1)) / count[:, None]
        mean_r = (patches @ r.sum(axis=1)) / count
        gg = gg - count[:, None, None] * mean_g[:, :, None] * mean_g[:, None, :]
        gr = gr - count[:, None] * mean_g * mean_r[:, None]
    elif brightness == "channel":
        mean_g = (patches @ grads.reshape(n, -1)).reshape(n, channels, 3) / total[:, None, None]
        mean_r = (patches @ r) / total[:, None]
        gg = gg - total[:, None, None] * np.einsum("nci,ncj->nij", mean_g, mean_g)
        gr = gr - total[:, None] * np.einsum("nci,nc->ni", mean_g, mean_r)
    system = tangent @ gg @ tangent.transpose(0, 2, 1)
    right = -np.einsum("nij,nj->ni", tangent, gr)
    # what the colour noise adds to the structure tensor, per tangent direction
    noise_energy = 0.5 * (patches @ noise.sum(axis=1))
    return system, right, residual, noise_energy


