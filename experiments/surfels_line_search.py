"""Question (issue 50, speed): the alignments' Gauss-Newton steps average 4.85 energy
evaluations each on crane, where every other optimisation of ``surfels`` takes 1.00. Can
fewer line-search trials, or a larger damping, cut that cost without a worse alignment?

Run from the repository root::

    PYTHONPATH=src .venv/bin/python experiments/surfels_line_search.py capture
    PYTHONPATH=src .venv/bin/python experiments/surfels_line_search.py compare
    PYTHONPATH=src .venv/bin/python experiments/surfels_line_search.py switches 0 17

``capture`` reconstructs the bench's crane (20 frames) and pickles every ``align_ranges``
optimisation (38 calls); ``compare`` reruns them with each variant and prints the time, the
energy evaluations per step, the final energies against the first variant's (12 halvings, the
default before) and how far the aligned surfels end from its (in ``eps_sampl``).

Answer (2-core Intel Xeon, nothing else running, 2026-12-06 at 3e0f7c5; 38 alignments, 280
steps with the default 12 halvings): the alignments' first steps are full steps, then the
accepted scale falls step after step to 2^-5 .. 2^-12, and each alignment ends with a step that
no scale accepts (13 evaluations). Per step: 1, 1, 1, 5, 10, 12, 13 evaluations, typically.

| variant | time | steps | evaluations/step | final energy / 12 halvings' | surfels moved (eps_sampl, median / max) |
|---|---|---|---|---|---|
| 12 halvings (default) | 58.1 s | 280 | 4.85 | 1 | 0 |
| 6 | 36.7 s | 230 | 2.90 | 1.000 - 1.001 | 0.000 / 0.000 |
| 4 | 27.7 s | 207 | 2.16 | 1.000 - 1.005 | 0.000 / 0.003 |
| 3 | 24.1 s | 199 | 1.86 | 1.000 - 1.005 | 0.000 / 0.003 |
| 2 | 21.6 s | 192 | 1.62 | 1.000 - 1.015 | 0.000 / 0.004 |
| start from twice the last accepted scale (an option tried, then removed) | 42.8 s (52.5 s for the default in that run) | 281 | 3.24 | 1.000 - 1.015 | 0.000 / 0.012 |
| damping 1e-2 | 56.3 s | 292 | 4.24 | 0.776 - 1.265 | 0.037 / 0.179 |
| damping 1e-1 | 50.8 s | 280 | 4.27 | 0.816 - 10.1 | 0.151 / 0.522 |

So 3 halvings would cut the alignments' time by 58% (about 30 s of crane's 300), and the
aligned surfels move by at most 0.003 eps_sampl. Not adopted: with the alignment's halvings
at 9 or fewer (3, 4, 5, 6, 8, 9 tried; an option ``align_halvings`` on
``assembly_schedule``'s ``align``), ``test_touching_spheres_are_not_glued_in_any_frame``
(3 frames at 128 rays, quick settings) fails: the mesh breaks into 4-5 pieces (1,359 + 690 +
674 + 192 + 95 vertices at 6 halvings) where 12 and 11 give the two spheres (1,806 + 1,344 +
a crumb of 8). The second merge's resampling keeps 984 surfels instead of 972 (8,434 edges
instead of 8,178) and the meshing's border clipping then cuts one sphere apart (checked: at 6
halvings with ``mesh_clip`` 0.3 instead of 0.4 the pieces join again, 2,070 + 1,419 + 125;
a band of that sphere has less than 0.4 of its surfels' own weight sum). Its surfels cover
the spheres patchily at this scan: before the final optimisation 20% of the truth's vertices
at frame 0 lie more than eps_sampl from the nearest surfel (some unseen), after it 29-30%
(43% at frame 1), the final pass moving the surfels by 0.57 eps_sampl (median; at 12 and at 6
halvings alike). The meshing of
that scene turns on a change of the alignment below 0.003 eps_sampl; until it is robust to
that, the line search keeps its 12 halvings.

Why the scale falls (2026-12-07, nineteenth session, at 828c9b3 plus ``line_search``): each
trial associates the data again, and in the alignment regime the cutoff (the largest distance
at percentile 100), the doublet test and the normal test switch points on and off between
trials, each inactive point worth ``omega tau^2``. Stepping through four of crane's alignments
(0, 5, 17, 30), the energy with the step's own association falls at the full step at every
step (-12%, -1%, -0.4%, then -0.1% .. -0.003%), while the energy associated again moves by
-2% .. +10% at the same trial with 1-30 points switched: after the third step the line search
compares noise, and halving only looks for a scale where the switches happen to fall well.

So a line search under the step's own association (``GaussNewtonOptions.line_search =
"fixed"``, the next step associating again; the option existed from bc76980 to 9247a4c, whose
``compare`` ran these variants) was tried, the final energies compared with the
data associated again for every variant (a second run; the default's time moves by 10%
between runs on this machine):

| variant | time | steps | evaluations/step | final energy / 12 halvings' (median, min - max) | surfels moved (eps_sampl, median / max) |
|---|---|---|---|---|---|
| 12 halvings (default) | 49.6 s | 280 | 4.85 | 1 | 0 |
| 3 halvings | 22.0 s | 199 | 1.86 | 1.000 (1.000 - 1.005) | 0.000 / 0.003 |
| fixed, tolerance 1e-6 (12 steps each) | 35.2 s | 456 | 1.00 | 1.013 (0.809 - 1.294) | 0.017 / 0.102 |
| fixed, tolerance 1e-4 | 35.3 s | 449 | 1.00 | 1.013 (0.809 - 1.294) | 0.017 / 0.102 |
| fixed, tolerance 1e-3 | 19.6 s | 226 | 1.00 | 1.016 (0.813 - 1.181) | 0.013 / 0.079 |

The fixed association is as fast as 3 halvings at a tolerance of 1e-3, ends 1.6% higher in the
energy of the paper (median; its constant counts the points switched off) and moves the
surfels 0.013 eps_sampl from the default's (median). Fewer halvings are no principle, only a
cheaper search among the switches, and they hurt where the late small steps were real
progress: the streamed test (9 frames of rigid-turn at 64 rays in windows of 4) tracked the
turn to 0.23-0.25 of the motion at 12 halvings, 0.24-0.28 at 6, 0.24-0.33 at 4 and 3 (3 also
meshed 1,076 vertices instead of 1,158), and 0.21-0.24 with the fixed association at 1e-3,
its vertices observed in 94% of the frames against 93%.

The fixed association at 1e-3 was then benched on crane (at 99bf033, where the alignments used
it; `fourd bench --methods surfels --scenes crane`, one run a side, nothing else running):
11.16 s/frame against 13.85 for 958d51a in the same hour (-19%), but every score worse:
Chamfer 0.0035 -> 0.0040, completeness-95 0.0149 -> 0.0159, correspondence 0.0090 -> 0.0099
mean and 0.0118 -> 0.0129 last. A last variant (``line_search = "checked"``, at 9247a4c): each step taken under its own association and kept only if the energy
associated again fell too, else the optimisation ends; 13.5 s against 47.9 for the 38
alignments (2.00 evaluations a step), final energies 1.003 of the default's (median) but up to
1.144, surfels moved up to 0.104 eps_sampl: it is 0 halvings in effect, and the alignments
that needed a smaller step stop short.

So each variant trades a scene: fewer halvings lose the rigid turn's late progress, the fixed
association loses crane's scores, and the search among the switches, though it mostly compares
noise, finds states of lower energy that track better. Not adopted; the alignments keep the
associated line search and 12 halvings. What would help: an energy without the switches
(a smooth cutoff instead of the percentile, the doublet and normal tests as weights that
fade), so that a step's decrease is not drowned; not tried then (the next session's below).

What switches, measured (2026-12-07, twentieth session; ``switches`` prints every trial's
energy against the step's, with the points whose nearest surfel or active flag differs from
the step's association). Alignment 17, the fifth step: +4.4e-2 (620 nearest surfels
changed, 133 points switched), +5.5e-2 (323, 80), +3.2e-3 (160, 34), +2.6e-3 (78, 20),
+4.1e-4 (41, 11), then -3.1e-3 (27, 5) accepted at 2^-5. Late steps end at trials where no
nearest surfel changes and one point switches, +9e-4 of the energy each time (about 60 of
65,284), until the scale is so small that nothing switches (-1.5e-6, accepted). So a single
point switched by the doublet or normal test outweighs the late steps' whole decrease. Three
more cures, each run on the 38 alignments (``compare``; the fade and common options exist in 802ea25 only):

| variant | time | steps | evaluations/step | final energy / 12 halvings' (median, min - max) | surfels moved (eps_sampl, median / max) |
|---|---|---|---|---|---|
| 12 halvings (default), same run | 63.9 s | 280 | 4.85 | 1 | 0 |
| ``tau`` held at the call's first association (``hold``) | 56.4 s | 279 | 4.82 | 1.000 (1.000 - 1.000) | 0.000 / 0.000 |
| the tests fading over +-20% of their thresholds (``fade 0.2 12``) | 62.9 s | 281 | 4.88 | 1.000 (0.980 - 1.000) | 0.000 / 0.004 |
| the same at 3 halvings, fading over +-10/20/40% | 27.6-30.7 s | 199-202 | 1.86 | 1.000 (0.965 - 1.005) | 0.000 / 0.004-0.006 |
| both energies over the points active in both associations (``common 12``) | 56.2 s | 429 | 1.93 | 1.019 (0.813 - 1.294) | 0.014 / 0.101 |
| the same at 3 halvings | 47.8 s | 404 | 1.34 | 1.018 (0.813 - 1.294) | 0.014 / 0.101 |

- Holding ``tau`` changes nothing: the switches' price is ``tau^2`` (the largest distance)
  against a switched point's own ``rho^2``, not ``tau``'s changes from trial to trial.
- Fading the tests makes each switch continuous but as steep (the share falls over a band the
  trial steps cross at once, and the Gauss-Newton model does not see the share's slope): the
  evaluations per step are unchanged.
- Comparing over the points active in both takes the switches out of the decision: 1.93
  evaluations a step, but it walks 50% more steps to the tolerance and ends where the fixed
  association ended (the same 1.019 median, the same 0.813 - 1.294 range, 0.014 eps_sampl
  from the default's surfels), the state that cost crane 10% on every score. Not benched.

So the switches are not noise the search could simply ignore: the states the associated line
search reaches by dodging them are the ones that track better. None adopted.

The touching-spheres test's scene was the outlier: 3 frames of a gap of 0.7 move each sphere
by 0.35 a frame (3.5 eps_sampl at 128 rays, 70% of its radius). At 12 halvings 20% of the
assembled surfels lie more than 0.14 from the truth at frame 0 (40% more than 0.1 at the
contact frame): the alignment lost track of that motion, and the test's two pieces depended on
which lost surfels the clipping kept. At a gap of 0.3 (0.15 a frame; the spheres 0.3 apart in
frames 0 and 2, more than eps_top = 0.2) the default, 3 halvings and the fixed association all
give the two spheres (3,315 + 1,755 vertices and a crumb of 37 for the first two, identical;
3,472 + 1,740 with the fixed association). At the gap of 0.7 the fixed association passes
too (2,655 + 1,289, no crumb), its surfels as lost (vertices 0.11 from the truth on average):
the test moved to the gap of 0.3, where a pass means a tracked motion.
"""

from __future__ import annotations

import dataclasses
import pickle
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PROBLEMS = Path(tempfile.gettempdir()) / "fourd-surfels-align-calls.pkl"


def capture() -> None:
    import fourd
    import fourd.methods.surfels.align as align
    from fourd.bench.suite import BenchScene, scan_scene

    _, scans = scan_scene(BenchScene("crane", frames=20, options={"start": 0, "step": 2}))
    calls = []
    solve = align.gauss_newton

    def keep(*args, **kwargs):
        calls.append((args, kwargs))
        return solve(*args, **kwargs)

    align.gauss_newton = keep
    fourd.reconstruct(scans, method="surfels")
    PROBLEMS.write_bytes(pickle.dumps(calls))
    print(f"{len(calls)} alignments kept in {PROBLEMS}")


def compare() -> None:
    import fourd.methods.surfels.optimizer as optimizer
    from fourd.methods.surfels.match import Matches, _squared_distance, associate

    calls = pickle.loads(PROBLEMS.read_bytes())
    evaluations = [0]
    energy = optimizer.total_energy

    def counting(*args, **kwargs):
        if not kwargs.get("derivatives", True):
            evaluations[0] += 1
        return energy(*args, **kwargs)

    optimizer.total_energy = counting
    # the first is the reference of the others
    variants = {
        "halvings 12": {"halvings": 12},
        "damping 1e-2": {"halvings": 12, "damping": 1e-2},
        "damping 1e-1": {"halvings": 12, "damping": 1e-1},
        "halvings 6": {"halvings": 6},
        "halvings 4": {"halvings": 4},
        "halvings 3": {"halvings": 3},
        "halvings 2": {"halvings": 2},
    }
    variants["hold 12"] = {"halvings": 12, "hold": True}
    variants["hold 3"] = {"halvings": 3, "hold": True}
    variants["common 12"] = {"halvings": 12, "line_search": "common"}
    variants["common 3"] = {"halvings": 3, "line_search": "common"}
    for fade in (0.1, 0.2, 0.4):
        for halvings in (12, 3):
            variants[f"fade {fade} {halvings}"] = {"halvings": halvings, "fade": fade}
    # the common and fade variants need the options of 802ea25; run them there, by name
    at_802ea25 = [name for name in variants if name.startswith(("common", "fade"))]
    if sys.argv[2:]:
        variants = {name: variants[name] for name in sys.argv[2:]}
    else:
        variants = {name: change for name, change in variants.items() if name not in at_802ea25}
    associated = optimizer.associate
    held = {}

    def holding(state, data, scale, match):
        # tau held at the call's first association (at percentile 100 it only prices the
        # points the doublet and normal tests reject)
        matches = associated(state, data, scale, match)
        if "tau" not in held:
            held["tau"] = matches.cutoff
            return matches
        rho = np.sqrt(_squared_distance(state, data, matches.surfels, match.tangential))
        return Matches(matches.surfels, matches.active & (rho <= held["tau"]), held["tau"])
    reference = None
    for name, change in variants.items():
        evaluations[0] = 0
        steps, finals, results = 0, [], []
        started = time.perf_counter()
        states = []
        for args, kwargs in calls:
            args = list(args)
            change = dict(change)
            hold = change.pop("hold", False)
            if "fade" in change:
                args[4] = dataclasses.replace(args[4], fade=change.pop("fade"))
            args[5] = dataclasses.replace(args[5], **change)
            optimizer.associate = holding if hold else associated
            held.clear()
            result = optimizer.gauss_newton(*args, **kwargs)
            optimizer.associate = associated
            steps += len(result.cg_iterations)
            states.append(result.state)
        elapsed = time.perf_counter() - started
        # the final energies with the data associated again, whatever the line search compared
        for (args, _), state in zip(calls, states, strict=True):
            _, topology, data, weights, match = args[:5]
            again = associate(state, data, topology.radius, match)
            finals.append(energy(state, topology, data, again, weights, match, derivatives=False).value)
            results.append(state.positions[1])
        finals = np.array(finals)
        if reference is None:
            reference = (finals, results)
        ratio = finals / reference[0]
        moved = [
            np.linalg.norm(a - b, axis=1).mean() / (args[1].radius / 2)
            for a, b, (args, _) in zip(results, reference[1], calls, strict=True)
        ]
        print(
            f"{name:>16}: {elapsed:6.1f} s, {steps} steps, "
            f"{evaluations[0] / max(steps, 1):.2f} evaluations/step; final energy / the first's "
            f"median {np.median(ratio):.3f} (min {ratio.min():.3f}, max {ratio.max():.3f}); "
            f"surfels from the first's {np.median(moved):.3f} eps_sampl median, "
            f"{np.max(moved):.3f} max"
        )


def switches() -> None:
    import fourd.methods.surfels.optimizer as optimizer
    from fourd.methods.surfels.match import associate

    calls = pickle.loads(PROBLEMS.read_bytes())
    events = []
    energy = optimizer.total_energy

    def associating(*args):
        matches = associate(*args)
        events.append(("association", matches))
        return matches

    def evaluating(*args, **kwargs):
        result = energy(*args, **kwargs)
        events.append(("energy", kwargs.get("derivatives", True), result.value, args[3]))
        return result

    optimizer.associate, optimizer.total_energy = associating, evaluating
    for k in (int(a) for a in sys.argv[2:] or ("0", "17")):
        events.clear()
        args, kwargs = calls[k]
        optimizer.gauss_newton(*args, **kwargs)
        print(f"alignment {k}: relative change (nearest surfels changed, points switched)")
        trials = []
        for event in events:
            if event[0] == "energy" and event[1]:
                if trials:
                    print("   ", " ".join(trials))
                trials, current, matches = [], event[2], event[3]
                print(f"  step from {current:.10g}")
            elif event[0] == "energy":
                again = event[3]
                trials.append(
                    f"{(event[2] - current) / current:+.2e}"
                    f"({np.sum(again.surfels != matches.surfels)},"
                    f"{np.sum(again.active != matches.active)})"
                )
        print("   ", " ".join(trials))


if __name__ == "__main__":
    {"capture": capture, "compare": compare, "switches": switches}[sys.argv[1]]()
