"""Question: where do the handles of ``assembly``'s dfaust-hopping mesh come from?

The closed result of all 17 frames has Euler characteristic -2 (genus 2), which a hopping
person does not have. Is the genus in the first frame's own mesh (the per-frame surface the
hierarchy starts from), or made by the merges?

Run: ``.venv/bin/python experiments/assembly_handles.py``

Answer (2026-12-04, 7247184): the first frame's mesh is one piece with Euler characteristic
-121 and 115 boundary loops (counted as the walk splits them at bow-ties). Capping each loop
by a disk would give genus 4. The handles are in the per-frame surface, made by marching cubes
where two parts of the body nearly touch in the scan. The merges fill the big loops from other
frames and the closing caps the small ones; no step removes a handle.
"""

from fourd import synth
from fourd.bench.runner import PROTOCOL
from fourd.geometry.boundary_loops import boundary_loops
from fourd.methods.assembly.method import _frame_meshes
from fourd.methods.assembly.options import Options
from fourd.metrics.topology import topology

if __name__ == "__main__":
    truth = synth.scene("dfaust-hopping", frames=2, seed=0)
    scans = synth.scan(truth, resolution=256, seed=0, **PROTOCOL)
    meshes, _ = _frame_meshes(scans, Options(), frames=slice(0, 1))
    vertices, faces = meshes[0][0], meshes[0][1]
    found = topology(faces, len(vertices))
    loops = boundary_loops(faces, len(vertices))
    print(found)
    print(f"{len(loops)} boundary loops, the longest {[len(loop) for loop in loops[:8]]} vertices")
    print(f"genus with every loop capped: {(2 * found.components - found.euler - len(loops)) / 2:g}")
