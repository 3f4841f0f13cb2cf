"""The 16-ary tree of the 4D MPU: child point lists."""

import numpy as np


def test_child_point_lists_filtered_from_the_parent_match_a_brute_force_ball_query():
    from fourd.methods.kinematic.mpu_fit import _CORNERS
    from fourd.methods.kinematic.mpu_tree import _child_counts, _child_fill

    rng = np.random.default_rng(5)
    X = rng.uniform(-1.0, 1.0, size=(3000, 4))
    centres = np.array([[0.0, 0.0, 0.0, 0.0], [0.3, -0.2, 0.1, 0.0]])
    half, alpha = 0.5, 0.75
    parent_r, child_half = 4.0 * alpha * half, half / 2.0
    child_r = 4.0 * alpha * child_half
    lists = [np.flatnonzero(np.linalg.norm(X - c, axis=1) <= parent_r) for c in centres]
    indptr = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
    indices = np.concatenate(lists).astype(np.int64)
    parents = np.array([0, 1], dtype=np.int64)
    counts = np.zeros(32, dtype=np.int64)
    inside = np.zeros(32, dtype=np.int64)
    masks = np.zeros(len(indices), dtype=np.uint16)
    _child_counts(X, indptr, indices, parents, centres, child_half, child_r, counts, inside, masks)
    slot = np.arange(32, dtype=np.int64)
    slot[7] = -1  # a dropped child
    kept = slot >= 0
    out_ptr = np.r_[0, np.cumsum(counts[kept])].astype(np.int64)
    out = np.empty(int(out_ptr[-1]), dtype=np.int64)
    slot[kept] = np.arange(int(kept.sum()))
    _child_fill(indptr, indices, parents, masks, slot, out_ptr, out)
    children = (centres[:, None, :] + child_half * _CORNERS[None]).reshape(-1, 4)
    for k, child in enumerate(children):
        d = X - child
        expect = np.flatnonzero(np.linalg.norm(d, axis=1) <= child_r)
        assert counts[k] == len(expect)
        assert inside[k] == np.sum(np.abs(d).max(axis=1) <= child_half)
        if slot[k] >= 0:
            got = out[out_ptr[slot[k]] : out_ptr[slot[k] + 1]]
            assert np.array_equal(np.sort(got), expect)
