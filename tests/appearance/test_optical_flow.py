import numpy as np
import pytest

from fourd.appearance.flow import forward_backward, gray, optical_flow, sample_flow, sample_image
from fourd.errors import InputError


def _texture(size=96, seed=0):
    import cv2

    rng = np.random.default_rng(seed)
    small = (rng.random((size // 6, size // 6, 3)) * 255).astype(np.uint8)
    return cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)


@pytest.mark.parametrize("method", ["dis", "farneback"])
def test_flow_recovers_a_known_shift(method):
    first = _texture()
    second = np.roll(first, (2, -3), axis=(0, 1))  # down 2, left 3
    flow = optical_flow(first, second, method=method)
    assert flow.shape == (96, 96, 2) and flow.dtype == np.float32
    inner = flow[16:-16, 16:-16].reshape(-1, 2)
    np.testing.assert_allclose(np.median(inner, axis=0), [-3, 2], atol=0.15)


def test_forward_backward_error_is_small_for_consistent_flow_and_large_otherwise():
    height, width = 20, 30
    forward = np.zeros((height, width, 2), np.float32)
    forward[..., 0] = 2.0
    backward = -forward
    uv = np.array([[5.0, 5.0], [10.5, 7.25]])
    moved, returned, error = forward_backward(forward, backward, uv)
    np.testing.assert_allclose(moved, uv + [2, 0])
    np.testing.assert_allclose(returned, uv)
    np.testing.assert_allclose(error, 0, atol=1e-12)
    _, _, error = forward_backward(forward, np.zeros_like(forward), uv)  # occluded: no way back
    np.testing.assert_allclose(error, 2.0)


def test_sampling_is_bilinear_between_pixel_centres():
    field = np.zeros((4, 4, 2))
    field[:, :, 0] = np.arange(4)[None, :]  # u-ramp
    field[:, :, 1] = np.arange(4)[:, None]  # v-ramp
    np.testing.assert_allclose(sample_flow(field, [[1.25, 2.5], [0.0, 0.0], [-3, 9]]), [[1.25, 2.5], [0, 0], [0, 3]])
    image = np.zeros((2, 2, 3), np.uint8)
    image[:, 1] = 255
    np.testing.assert_allclose(sample_image(image, [[0.5, 0.5]]), [[0.5, 0.5, 0.5]])


def test_bad_images():
    with pytest.raises(InputError, match="uint8"):
        gray(np.zeros((4, 4, 3)))
    with pytest.raises(InputError, match="different sizes"):
        optical_flow(np.zeros((8, 8), np.uint8), np.zeros((8, 9), np.uint8))
    with pytest.raises(InputError, match="unknown flow method"):
        optical_flow(np.zeros((8, 8), np.uint8), np.zeros((8, 8), np.uint8), method="lk")
