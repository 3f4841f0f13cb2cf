"""three.js reads fourd's quantized .glb: the viewer's own bundled three.js (r181 GLTFLoader)
in headless Chromium decodes positions and morphed normals as fourd meant them. Plain
``chromium --dump-dom`` (no playwright); skipped without Chromium."""

from __future__ import annotations

import base64
import html
import json
import os
import re
import subprocess
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fourd.animation import AnimatedMesh
from fourd.geometry.normals import vertex_normals
from fourd.io.results import save

pytestmark = pytest.mark.browser

PROBE = """<!doctype html><html><body><script>{three}</script><script>
var bytes = Uint8Array.from(atob("{glb}"), function (c) {{ return c.charCodeAt(0); }});
function report(value) {{
  var pre = document.createElement("pre"); pre.id = "probe";
  pre.textContent = JSON.stringify(value); document.body.appendChild(pre);
}}
new THREE.GLTFLoader().parse(bytes.buffer, "", function (gltf) {{
  var mesh = null;
  gltf.scene.traverse(function (o) {{ if (o.isMesh) mesh = o; }});
  gltf.scene.updateMatrixWorld(true);
  var g = mesh.geometry, n = g.getAttribute("position").count, base = g.getAttribute("normal");
  var out = {{positions: [], normals: []}}, v = new THREE.Vector3();
  for (var k = 0; k <= mesh.morphTargetInfluences.length; k++) {{
    for (var j = 0; j < mesh.morphTargetInfluences.length; j++) mesh.morphTargetInfluences[j] = j === k - 1 ? 1 : 0;
    var delta = k ? g.morphAttributes.normal[k - 1] : null, P = [], N = [];
    for (var i = 0; i < n; i++) {{
      mesh.getVertexPosition(i, v); v.applyMatrix4(mesh.matrixWorld); P.push([v.x, v.y, v.z]);
      var x = base.getX(i), y = base.getY(i), z = base.getZ(i);
      if (delta) {{ x += delta.getX(i); y += delta.getY(i); z += delta.getZ(i); }}
      N.push([x, y, z]);  // the shader normalizes the morphed normal
    }}
    out.positions.push(P); out.normals.push(N);
  }}
  report(out);
}}, function (error) {{ report({{error: String(error)}}); }});
</script></body></html>"""


def _half_turn(frames=4) -> AnimatedMesh:
    """A sphere swelling and turning half a turn about y: its normals reverse."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    vertices = []
    for t in range(frames):
        angle = np.pi * t / (frames - 1)
        c, s = np.cos(angle), np.sin(angle)
        turn = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        vertices.append(sphere.vertices * [1, 1 + 0.3 * t, 1] @ turn.T + [0.5 * t, 0, 0])
    return AnimatedMesh(sphere.faces, np.stack(vertices))


def test_three_js_decodes_the_quantized_morph_targets(tmp_path):
    chromium = os.environ.get("FOURD_CHROMIUM", "/usr/bin/chromium")
    if not Path(chromium).exists():
        pytest.skip(f"no Chromium at {chromium}")
    anim = _half_turn()
    save(anim, tmp_path / "r.glb")  # quantized, the default
    three = resources.files("fourd.viz").joinpath("static/three.fourd.min.js").read_text()
    glb = base64.b64encode((tmp_path / "r.glb").read_bytes()).decode("ascii")
    (tmp_path / "probe.html").write_text(PROBE.format(three=three, glb=glb))
    command = [chromium, "--headless=new", "--no-sandbox", "--disable-gpu",
               "--virtual-time-budget=20000", "--dump-dom", (tmp_path / "probe.html").as_uri()]
    dom = subprocess.run(command, capture_output=True, text=True, timeout=120).stdout
    found = re.search(r'<pre id="probe">(.*?)</pre>', dom, re.S)
    assert found, f"the page reported nothing: {dom[-500:]}"
    report = json.loads(html.unescape(found.group(1)))
    assert "error" not in report, report
    positions = np.array(report["positions"])
    assert np.abs(positions - anim.vertices).max() <= 2e-5 * anim.diagonal()
    normals = np.array(report["normals"])
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    cosine = np.einsum("tij,tij->ti", normals, vertex_normals(anim.vertices, anim.faces))
    assert cosine.min() >= np.cos(np.radians(1.0))
