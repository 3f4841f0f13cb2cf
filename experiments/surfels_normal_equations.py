"""Question: where does one Gauss-Newton step of `surfels` spend its time, and would a
different assembly of the normal equations make it cheaper?

Runs `surfels` on the bench's crane scan cut to FRAMES frames (default 8), keeps the largest
global optimisation's energy call (all unknowns free), and on it times: each term's residuals
and Jacobian entries, each term's ``J^T J``, the sum of the terms' products (what
`energy.total_energy` does), the same with every term's rows stacked into one Jacobian and one
product, and one product of the Hessian with a vector (what each conjugate-gradient iteration
does); with the Hessian's nonzeros per term.

    PYTHONPATH=src python experiments/surfels_normal_equations.py [FRAMES]

Answer (2-core AMD EPYC, 2026-12-01, at 6a3fc30; 8 frames, 1,314 surfels, 18,010 directed
edges, 80,154 unknowns): the Hessian has 11.7 million nonzeros, 146 a row; the rigidity term
(eq. 9, whose rotations couple a surfel's position with every neighbour's in two frames) makes
8.1 million of them, the smoothness of positions (eq. 6) 3.3 million. The terms' residuals and
entries take 0.26 s, their six `J^T J` products 0.46 s, the products summed 0.56 s; one
stacked product is slower (0.59 s). One Hessian-vector product takes 6 ms, so 50
conjugate-gradient iterations cost about half an assembly. At 3b2f375 a variant that dropped
the fixed unknowns' entries before each product instead of multiplying by a selection matrix
saved about 7% on a restricted call (0.50-0.52 -> 0.47-0.50 s), within this machine's spread,
and was reverted. So the cost is the size of the system, not its assembly: what would change
it is a smaller system (the rotations eliminated per step, as-rigid-as-possible style, leaving
the positions' sparser pattern; fewer frames optimised per merge), not a faster product.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import scipy.sparse as sp


def best_of(function, repeats=3):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


def main():
    import fourd.bench.suite as suite
    import fourd.methods.surfels.optimizer as optimizer
    from fourd import synth
    from fourd.methods import reconstruct
    from fourd.methods.surfels import match as match_terms
    from fourd.methods.surfels import motion, smoothness

    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    original = optimizer.total_energy
    largest = {}

    def recording(state, topology, data, matches, weights=None, match=None, **options):
        if options.get("derivatives", True) and options.get("columns") is None:
            if state.count * state.frames >= largest.get("size", 0):
                largest.update(
                    size=state.count * state.frames,
                    call=(state, topology, data, matches, weights, match),
                )
        return original(state, topology, data, matches, weights, match, **options)

    optimizer.total_energy = recording
    truth = synth.scene("crane", frames=frames)
    scans = synth.scan(truth, resolution=256, seed=0, **suite.PROTOCOL)
    reconstruct(scans, "surfels")
    optimizer.total_energy = original

    state, topology, data, matches, w, options = largest["call"]
    builders = {
        "match": lambda: match_terms.match_term(state, data, matches, w.match, options),
        "smooth_position": lambda: smoothness.smooth_position_term(
            state, topology, w.smooth_position
        ),
        "smooth_normal": lambda: smoothness.smooth_normal_term(state, topology, w.smooth_normal),
        "laplace": lambda: smoothness.laplace_term(state, topology, w.laplace),
        "rigid": lambda: motion.rigid_term(state, topology, w.rigid, w.rigid_normal),
        "accel": lambda: motion.accel_term(state, w.accel, w.accel_normal),
    }
    print(f"{state.frames} frames, {state.count} surfels, {len(topology.directed)} directed edges")
    parts, build_total, product_total = [], 0.0, 0.0
    for name, build in builders.items():
        seconds, part = best_of(lambda b=build: (lambda t: (t, t.jacobian))(b())[0])
        jacobian = part.jacobian
        product, hessian = best_of(lambda j=jacobian: j.T @ j)
        build_total += seconds
        product_total += product
        parts.append(jacobian)
        print(
            f"{name:16s} J {jacobian.nnz:9d} entries, H {hessian.nnz:9d} nonzeros; "
            f"term {seconds:.3f} s, J^T J {product:.3f} s"
        )
    size = parts[0].shape[1]

    def summed():
        total = sp.csr_matrix((size, size))
        for jacobian in parts:
            total = total + jacobian.T @ jacobian
        return total.tocsr()

    def stacked():
        jacobian = sp.vstack(parts, format="csr")
        return (jacobian.T @ jacobian).tocsr()

    seconds_sum, hessian = best_of(summed)
    seconds_stack, _ = best_of(stacked)
    vector = np.random.default_rng(0).normal(size=size)
    seconds_product, _ = best_of(lambda: hessian @ vector, repeats=10)
    print(f"unknowns {size}, Hessian {hessian.nnz} nonzeros ({hessian.nnz / size:.0f} a row)")
    print(
        f"terms {build_total:.3f} s; products {product_total:.3f} s; "
        f"summed products {seconds_sum:.3f} s; one stacked product {seconds_stack:.3f} s; "
        f"one Hessian-vector product {seconds_product * 1000:.1f} ms"
    )


if __name__ == "__main__":
    main()
