"""Every kind of .glb fourd writes passes the Khronos glTF validator with no error or warning
(the npm package installed by .ci/run in tests/viz/browser; skipped where node or it is missing)."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fourd import AnimatedMesh, MeshSequence, save

MODULES = Path(__file__).resolve().parents[1] / "viz" / "browser" / "node_modules"
SCRIPT = """
const validator = require(process.argv[1]);  // node -e: argv[1] is the first argument
const fs = require('fs');
validator.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))
  .then((r) => console.log(JSON.stringify({errors: r.issues.numErrors, warnings: r.issues.numWarnings,
                                           messages: r.issues.messages.slice(0, 5)})))
  .catch((e) => { console.error(String(e)); process.exit(1); });
"""


def _validate(path: Path) -> dict:
    out = subprocess.run(["node", "-e", SCRIPT, str(MODULES / "gltf-validator"), str(path)],
                         capture_output=True, text=True, timeout=120, check=True)
    return json.loads(out.stdout)


def _animation():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    frames = np.stack([sphere.vertices * (1 + 0.1 * k) + [0.2 * k, 0, 0] for k in range(4)])
    return AnimatedMesh(sphere.faces, frames, times=np.arange(4.0))


@pytest.mark.skipif(shutil.which("node") is None or not (MODULES / "gltf-validator").is_dir(),
                    reason="node or the gltf-validator npm package is not installed")
@pytest.mark.parametrize("kind", ["quantized", "float", "sequence"])
def test_the_khronos_validator_finds_no_error_or_warning(tmp_path, kind):
    if kind == "sequence":
        anim = _animation()
        result = MeshSequence(tuple((v, anim.faces) for v in anim.vertices), anim.times)
        save(result, tmp_path / "r.glb")
    else:
        save(_animation(), tmp_path / "r.glb", glb_encoding=kind)
    report = _validate(tmp_path / "r.glb")
    assert (report["errors"], report["warnings"]) == (0, 0), report["messages"]
