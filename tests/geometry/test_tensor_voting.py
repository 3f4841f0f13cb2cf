import numpy as np
import pytest

from fourd.geometry.tensor_voting import _adjugate, tensor_voting


def _sphere(rng, count=4000, noise=0.01):
    points = rng.normal(size=(count, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    return normals + rng.normal(scale=noise, size=normals.shape), normals


def _plane(rng, count=4000, noise=0.01):
    points = np.c_[rng.uniform(-1, 1, (count, 2)), rng.normal(0, noise, count)]
    return points, np.tile([0.0, 0.0, 1.0], (count, 1))


def _scores(votes, surface_count):
    kept_surface = votes.keep[:surface_count]
    kept_outliers = votes.keep[surface_count:]
    recall = kept_surface.mean()
    precision = kept_surface.sum() / (kept_surface.sum() + kept_outliers.sum())
    return recall, precision, kept_outliers


@pytest.mark.parametrize(
    "shape, box, height, min_recall",
    # the plane's square border loses a few corner points (fewer voters)
    [
        (_sphere, 1.2, lambda o: np.abs(np.linalg.norm(o, axis=1) - 1), 0.995),
        (_plane, 1.0, lambda o: np.abs(o[:, 2]), 0.985),
    ],
)
def test_keeps_the_surface_drops_uniform_outliers(shape, box, height, min_recall):
    rng = np.random.default_rng(0)
    surface, truth = shape(rng)
    outliers = rng.uniform(-box, box, (len(surface) // 10, 3))
    votes = tensor_voting(np.concatenate([surface, outliers]))
    recall, precision, kept_outliers = _scores(votes, len(surface))
    # measured: sphere 0.9998 / 0.992, plane 0.989 / 0.9965
    assert recall >= min_recall
    assert precision >= 0.99
    # outliers within a voting scale of the surface are indistinguishable from noise
    far = height(outliers) > 2 * votes.sigma
    assert far.mean() > 0.5 and kept_outliers[far].mean() <= 0.01
    assert kept_outliers.mean() <= 0.1
    alignment = np.abs(np.einsum("ij,ij->i", votes.normals[: len(surface)], truth))
    assert np.median(alignment) > 0.99 and np.percentile(alignment, 5) > 0.9


def test_the_ratio_alone_keeps_sparse_outliers():
    # a point receiving one vote has a pure stick tensor: why min_saliency exists
    rng = np.random.default_rng(1)
    surface, _ = _sphere(rng)
    outliers = rng.uniform(-1.2, 1.2, (400, 3))
    votes = tensor_voting(np.concatenate([surface, outliers]), min_saliency=0.0)
    recall, _, kept_outliers = _scores(votes, len(surface))
    assert recall > 0.995 and kept_outliers.mean() > 0.8
    assert np.all(votes.ratio[: len(surface)][votes.keep[: len(surface)]] <= 0.8)


def test_isolated_points_get_no_votes():
    rng = np.random.default_rng(2)
    surface, _ = _plane(rng, count=1500)
    lonely = np.array([[0.0, 0.0, 50.0], [50.0, 0.0, 0.0]])
    votes = tensor_voting(np.concatenate([surface, lonely]))
    assert not votes.keep[-2:].any()
    assert np.all(votes.ratio[-2:] == 1.0) and np.all(votes.saliency[-2:] == 0.0)


def test_adjugate_sums_the_cross_product_votes():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(7, 3))
    w = rng.uniform(size=7)
    covariance = np.einsum("k,ka,kb->ab", w, a, a)
    pairs = sum(
        w[j] * w[k] * np.outer(np.cross(a[j], a[k]), np.cross(a[j], a[k]))
        for j in range(7)
        for k in range(j + 1, 7)
    )
    assert np.allclose(_adjugate(covariance[None])[0], pairs, atol=1e-12)


@pytest.mark.parametrize(
    "points, options",
    [
        (np.zeros((10, 2)), {}),
        (np.zeros((2, 3)), {}),
        (np.zeros((10, 3)), {"max_ratio": 0.0}),
        (np.zeros((10, 3)), {"max_angle": 90.0}),
        (np.zeros((10, 3)), {"scale": -1.0}),
    ],
)
def test_bad_input_raises(points, options):
    with pytest.raises(ValueError):
        tensor_voting(points, **options)
