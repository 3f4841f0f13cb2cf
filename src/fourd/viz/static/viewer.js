/* fourd viewer: plays an animated mesh (or a mesh sequence) with three.js.
 *
 * A classic script (no ES modules, no fetch) so the page works opened from a local file as
 * well as served over HTTP. It expects the global THREE (three.fourd.min.js: three.js plus
 * GLTFLoader and OrbitControls) and window.FOURD_DATA written by fourd.viz.viewer.
 *
 * Optional parts, present when the data has them: the "carried colour" colouring (frame 0's
 * vertex colours kept on every frame, the input points in their own colours beside them) and
 * the video panel (the input's camera images, one per frame, with the mesh's outline projected
 * over them through the camera's K, R, t).
 *
 * Test hooks: window.fourdReady (true once the model and the optional .glb are loaded and
 * frame 0 is drawn), window.fourdSetFrame(i), window.fourdInfo, window.fourdPixels(),
 * window.fourdGlbCheck(i), window.fourdVideo(), window.fourdErrors (problems caught while
 * loading).
 */
(function () {
  "use strict";
  var D = window.FOURD_DATA;
  window.fourdReady = false;
  window.fourdErrors = [];

  function fail(message) {
    window.fourdErrors.push(String(message));
    var box = document.getElementById("fourd-status");
    if (box) box.textContent = "Error: " + message;
    console.error("fourd viewer: " + message);
  }

  // an uncaught error ends the wait of a test (and shows on the page) instead of hanging it
  window.addEventListener("error", function (e) { fail(e.message || "script error"); });

  function decode(b64, Type) {
    if (b64 === undefined || b64 === null) return null;
    if (b64 === "") return new Type(0);
    var bin = atob(b64);
    var bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return Type === Uint8Array ? bytes : new Type(bytes.buffer);
  }

  if (!D) { fail("no data (FOURD_DATA missing)"); return; }
  if (typeof THREE === "undefined") { fail("three.js did not load"); return; }

  // ------------------------------------------------------------------ data
  var T = D.frameCount;
  var times = D.times;
  var animated = D.kind === "animated";
  var frames = [];          // per frame: {positions: Float32Array, faces: Uint32Array}
  var texcoordFirst = null; // animated: first-frame texture coordinates (fixed)
  var observed = decode(D.observed, Uint8Array);   // [T*N] or null
  var errors = decode(D.errors, Float32Array);     // [T*N] or null (animated)
  var lut = D.colormap;                            // [[r,g,b], ...] sRGB 0..1
  var N = 0;
  if (animated) {
    var all = decode(D.positions, Float32Array);
    var faces = decode(D.faces, Uint32Array);
    N = D.vertexCount;
    for (var t = 0; t < T; t++) frames.push({ positions: all.subarray(t * N * 3, (t + 1) * N * 3), faces: faces });
  } else {
    for (var t2 = 0; t2 < T; t2++) {
      frames.push({ positions: decode(D.frames[t2].positions, Float32Array), faces: decode(D.frames[t2].faces, Uint32Array),
                    errors: decode(D.frames[t2].errors, Float32Array) });
    }
  }
  var points = (D.points || []).map(function (p) { return decode(p, Float32Array); });
  // sRGB bytes [3 * n] -> linear floats, the space the shader multiplies colours in
  var toLinear = [];
  for (var b = 0; b < 256; b++) { var x = b / 255; toLinear.push(x <= 0.04045 ? x / 12.92 : Math.pow((x + 0.055) / 1.055, 2.4)); }
  function linearColors(bytes) {
    if (!bytes) return null;
    var out = new Float32Array(bytes.length);
    for (var k = 0; k < bytes.length; k++) out[k] = toLinear[bytes[k]];
    return out;
  }
  var carried = linearColors(decode(D.carriedColors, Uint8Array));            // [N*3] or null
  var pointColors = (D.pointColors || []).map(function (c) { return linearColors(decode(c, Uint8Array)); });
  var video = D.video || null;

  function textureCoords(pos) {
    var out = new Float32Array(pos.length);
    var o = D.texture.origin, c = D.texture.cell;
    for (var i = 0; i < pos.length; i += 3) {
      out[i] = (pos[i] - o[0]) / c; out[i + 1] = (pos[i + 1] - o[1]) / c; out[i + 2] = (pos[i + 2] - o[2]) / c;
    }
    return out;
  }
  if (animated) texcoordFirst = textureCoords(frames[0].positions);

  // ------------------------------------------------------------------ scene
  var canvas = document.getElementById("fourd-canvas");
  var renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0xffffff, 1);
  var scene = new THREE.Scene();
  var lo = new THREE.Vector3().fromArray(D.bounds[0]), hi = new THREE.Vector3().fromArray(D.bounds[1]);
  var center = lo.clone().add(hi).multiplyScalar(0.5);
  var radius = Math.max(lo.distanceTo(hi) * 0.5, 1e-9);
  var camera = new THREE.PerspectiveCamera(30, 1, radius * 0.01, radius * 100);
  var dir = new THREE.Vector3(Math.sin(0.61) * Math.cos(0.35), Math.sin(0.35), Math.cos(0.61) * Math.cos(0.35));
  camera.position.copy(center).addScaledVector(dir, radius / Math.sin(15 * Math.PI / 180) * 1.02);
  camera.lookAt(center);
  var controls = new THREE.OrbitControls(camera, canvas);
  controls.target.copy(center);
  controls.update();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x555555, 0.9));
  var headlight = new THREE.DirectionalLight(0xffffff, 1.6);
  headlight.position.set(-0.45, 0.65, 0.6);
  camera.add(headlight);
  scene.add(camera);

  function srgb(rgb) { return new THREE.Color().setRGB(rgb[0], rgb[1], rgb[2], THREE.SRGBColorSpace); }
  var uniforms = {
    fourdMode: { value: 1 },          // 0 none, 1 checker, 2 grid
    fourdUseColor: { value: 0 },      // 1: error colours from the attribute
    fourdShowFilled: { value: 1 },
    fourdDark: { value: srgb(D.palette.dark) },
    fourdLight: { value: srgb(D.palette.light) },
    fourdClay: { value: srgb(D.palette.clay) },
    fourdTint: { value: srgb(D.palette.tint) },
  };
  // pushed back a little in depth so that input points lying on the surface draw over it
  var material = new THREE.MeshLambertMaterial({ color: 0xffffff, side: THREE.DoubleSide,
    polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
  material.onBeforeCompile = function (shader) {
    Object.assign(shader.uniforms, uniforms);
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", "#include <common>\nattribute vec3 fourdTex;\nattribute vec3 fourdColor;\nattribute float fourdFilled;\nvarying vec3 vFourdTex;\nvarying vec3 vFourdColor;\nvarying float vFourdFilled;")
      .replace("#include <begin_vertex>", "#include <begin_vertex>\nvFourdTex = fourdTex;\nvFourdColor = fourdColor;\nvFourdFilled = fourdFilled;");
    shader.fragmentShader = shader.fragmentShader
      .replace("#include <common>", "#include <common>\nuniform int fourdMode;\nuniform int fourdUseColor;\nuniform int fourdShowFilled;\nuniform vec3 fourdDark;\nuniform vec3 fourdLight;\nuniform vec3 fourdClay;\nuniform vec3 fourdTint;\nvarying vec3 vFourdTex;\nvarying vec3 vFourdColor;\nvarying float vFourdFilled;")
      .replace("#include <color_fragment>", [
        "float fourdP = 1.0;",
        "if (fourdMode == 1) { vec3 c = floor(vFourdTex); fourdP = 1.0 - mod(c.x + c.y + c.z, 2.0); }",
        "else if (fourdMode == 2) { vec3 f = fract(vFourdTex); vec3 g = min(f, 1.0 - f); fourdP = step(0.04, min(g.x, min(g.y, g.z))); }",
        "vec3 fourdCol;",
        "if (fourdUseColor == 1) { fourdCol = vFourdColor * (fourdMode == 0 ? 1.0 : 0.55 + 0.45 * fourdP); }",
        "else if (fourdMode == 1) { fourdCol = mix(fourdDark, fourdLight, fourdP); }",
        "else if (fourdMode == 2) { fourdCol = mix(vec3(0.03, 0.035, 0.06), fourdClay, fourdP); }",
        "else { fourdCol = fourdClay; }",
        "if (fourdShowFilled == 1) { fourdCol = mix(fourdCol, fourdTint, 0.65 * clamp(vFourdFilled, 0.0, 1.0)); }",
        "diffuseColor.rgb *= fourdCol;",
      ].join("\n"));
  };

  var geometry = new THREE.BufferGeometry();
  var mesh = new THREE.Mesh(geometry, material);
  scene.add(mesh);
  var bluePoints = new THREE.PointsMaterial({ color: 0x1f4e9a, size: D.pointSize || radius * 0.01, sizeAttenuation: true });
  // carried colour: the points in their own recorded colours, drawn larger (about half their
  // spacing on screen) so that their colour reads against the mesh's between them
  var ownColorPoints = new THREE.PointsMaterial({ vertexColors: true, size: 3 * (D.pointSize || radius * 0.01), sizeAttenuation: true });
  var pointCloud = new THREE.Points(new THREE.BufferGeometry(), bluePoints);
  pointCloud.visible = false;
  scene.add(pointCloud);

  var lutLinear = lut.map(function (c) { var k = srgb(c); return [k.r, k.g, k.b]; });
  function errorColors(err) {
    var out = new Float32Array(err.length * 3);
    var n = lutLinear.length - 1, s = D.errorScale || 1;
    for (var i = 0; i < err.length; i++) {
      var k = Math.max(0, Math.min(n, Math.round((err[i] / s) * n)));
      out[3 * i] = lutLinear[k][0]; out[3 * i + 1] = lutLinear[k][1]; out[3 * i + 2] = lutLinear[k][2];
    }
    return out;
  }

  // ------------------------------------------------------------------ state
  var state = { frame: 0, playing: false, speed: 1, clock: 0, texture: "checker", showPoints: false,
                showFilled: true, showErrors: false, showCarried: false, showGlb: false,
                camera: 0, showOutline: true };
  var glb = null; // {root, mixer, clip, keyTimes, meshes}

  // frames without triangles (a point-sequence result) are drawn as points, checker-coloured
  var vertexPoints = new THREE.Points(new THREE.BufferGeometry(),
    new THREE.PointsMaterial({ size: D.vertexPointSize || radius * 0.02, vertexColors: true, sizeAttenuation: true }));
  scene.add(vertexPoints);
  function setVertexPoints(f) {
    var n = f.positions.length / 3;
    var coords = animated ? texcoordFirst : textureCoords(f.positions);
    var colors = new Float32Array(n * 3);
    if (state.showCarried && carried) colors.set(carried);
    else {
    // the light check is darkened a little so points stay visible on the white background
    var dark = uniforms.fourdDark.value, light = uniforms.fourdClay.value.clone().multiplyScalar(0.7);
    for (var v = 0; v < n; v++) {
      var odd = (Math.floor(coords[3 * v]) + Math.floor(coords[3 * v + 1]) + Math.floor(coords[3 * v + 2])) & 1;
      var c = odd ? dark : light;
      colors[3 * v] = c.r; colors[3 * v + 1] = c.g; colors[3 * v + 2] = c.b;
    }
    }
    vertexPoints.geometry.dispose();
    vertexPoints.geometry = new THREE.BufferGeometry();
    vertexPoints.geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(f.positions), 3));
    vertexPoints.geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3));
  }

  function setGeometry(i) {
    var f = frames[i];
    var n = f.positions.length / 3;
    vertexPoints.visible = f.faces.length === 0 && n > 0;
    if (vertexPoints.visible) setVertexPoints(f);
    var sameTopology = animated && geometry.getAttribute("position");
    if (sameTopology) {
      geometry.getAttribute("position").array.set(f.positions);
      geometry.getAttribute("position").needsUpdate = true;
    } else {
      geometry.dispose();
      geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(f.positions), 3));
      geometry.setIndex(new THREE.BufferAttribute(f.faces, 1));
      geometry.setAttribute("fourdTex", new THREE.BufferAttribute(animated ? texcoordFirst : textureCoords(f.positions), 3));
      geometry.setAttribute("fourdColor", new THREE.BufferAttribute(new Float32Array(n * 3).fill(1), 3));
      geometry.setAttribute("fourdFilled", new THREE.BufferAttribute(new Float32Array(n), 1));
      mesh.geometry = geometry;
    }
    var filled = geometry.getAttribute("fourdFilled");
    if (observed) {
      for (var v = 0; v < n; v++) filled.array[v] = observed[i * n + v] ? 0 : 1;
      filled.needsUpdate = true;
    }
    var err = animated ? (errors ? errors.subarray(i * n, (i + 1) * n) : null) : f.errors;
    if (state.showCarried && carried) {
      geometry.getAttribute("fourdColor").array.set(carried);
      geometry.getAttribute("fourdColor").needsUpdate = true;
    } else if (err && state.showErrors) {
      geometry.getAttribute("fourdColor").array.set(errorColors(err));
      geometry.getAttribute("fourdColor").needsUpdate = true;
    }
    geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
  }

  function setPoints(i) {
    if (!points.length) return;
    var k = Math.min(i, points.length - 1);
    pointCloud.geometry.dispose();
    pointCloud.geometry = new THREE.BufferGeometry();
    pointCloud.geometry.setAttribute("position", new THREE.BufferAttribute(points[k], 3));
    var own = state.showCarried && pointColors.length > 0;
    if (own) pointCloud.geometry.setAttribute("color", new THREE.BufferAttribute(pointColors[k], 3));
    pointCloud.material = own ? ownColorPoints : bluePoints;
  }

  function setGlbFrame(i) {
    if (!glb || !glb.action) return;
    // Put the clip exactly on key i. (mixer.setTime would wrap the last key, at the clip's
    // duration, back to the first under the default LoopRepeat.) update(0) evaluates the
    // tracks at action.time without advancing or wrapping it.
    var t = glb.keyTimes ? glb.keyTimes[Math.min(i, glb.keyTimes.length - 1)] : times[i] - times[0];
    glb.action.enabled = true;
    glb.action.paused = false;
    glb.action.time = Math.max(0, Math.min(t, glb.clip.duration));
    glb.mixer.update(0);
  }

  function applyUniforms() {
    uniforms.fourdMode.value = { none: 0, checker: 1, grid: 2 }[state.texture];
    uniforms.fourdUseColor.value = (state.showCarried && carried) || (state.showErrors && D.hasErrors) ? 1 : 0;
    uniforms.fourdShowFilled.value = state.showFilled ? 1 : 0;
    pointCloud.visible = state.showPoints && points.length > 0;
    if (glb) { glb.root.visible = state.showGlb; mesh.visible = !state.showGlb; }
  }

  function draw() {
    applyUniforms();
    renderer.render(scene, camera);
  }

  function setFrame(i) {
    i = Math.max(0, Math.min(T - 1, Math.round(Number(i)) || 0));
    state.frame = i;
    setGeometry(i);
    setPoints(i);
    setGlbFrame(i);
    setVideo(i);
    var slider = document.getElementById("fourd-frame");
    if (slider) slider.value = String(i);
    var label = document.getElementById("fourd-frame-label");
    if (label) label.textContent = "frame " + i + " / " + (T - 1) + "   t = " + Number(times[i]).toPrecision(4);
    draw();
    return { frame: i, time: times[i] };
  }

  // ------------------------------------------------------------------ video panel
  var videoImage = document.getElementById("fourd-video-image");
  var overlay = document.getElementById("fourd-video-overlay");
  var edgeCache = [];  // [{faces, edges: Uint32Array [E*4]: a, b, face1, face2 (face2 = -1: border)}]
  var outlineEdges = 0;

  function faceEdges(faces) {
    for (var c = 0; c < edgeCache.length; c++) if (edgeCache[c].faces === faces) return edgeCache[c].edges;
    var seen = new Map(), list = [];
    var big = 4294967296;
    for (var f = 0; f < faces.length / 3; f++) {
      for (var k = 0; k < 3; k++) {
        var a = faces[3 * f + k], b = faces[3 * f + (k + 1) % 3];
        var key = a < b ? a * big + b : b * big + a;
        var at = seen.get(key);
        if (at === undefined) { seen.set(key, list.length); list.push(a, b, f, -1); }
        else if (list[at + 3] === -1) list[at + 3] = f;
      }
    }
    var edges = new Int32Array(list);
    edgeCache.push({ faces: faces, edges: edges });
    if (edgeCache.length > 4) edgeCache.shift();
    return edges;
  }

  // the outline of frame i seen from camera c: border edges of front faces and edges between
  // a front and a back face, projected with K, R, t (OpenCV convention, pixel centres at
  // integers) onto the overlay canvas
  function drawOutline(i, c) {
    var ctx = overlay.getContext("2d");
    var box = overlay.getBoundingClientRect();
    var dpr = window.devicePixelRatio || 1;
    overlay.width = Math.max(1, Math.round(box.width * dpr));
    overlay.height = Math.max(1, Math.round(box.height * dpr));
    ctx.clearRect(0, 0, overlay.width, overlay.height);
    outlineEdges = 0;
    if (!state.showOutline) return;
    var f = frames[i], pos = f.positions, faces = f.faces;
    if (!faces.length) return;
    var K = c.K, R = c.R, t = c.t;
    var center = [0, 1, 2].map(function (j) { return -(R[0][j] * t[0] + R[1][j] * t[1] + R[2][j] * t[2]); });
    var F = faces.length / 3, front = new Uint8Array(F);
    for (var q = 0; q < F; q++) {
      var a = 3 * faces[3 * q], b = 3 * faces[3 * q + 1], d = 3 * faces[3 * q + 2];
      var ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
      var vx = pos[d] - pos[a], vy = pos[d + 1] - pos[a + 1], vz = pos[d + 2] - pos[a + 2];
      var nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      front[q] = nx * (center[0] - pos[a]) + ny * (center[1] - pos[a + 1]) + nz * (center[2] - pos[a + 2]) > 0 ? 1 : 0;
    }
    var sx = overlay.width / c.width, sy = overlay.height / c.height;
    function pixel(v) {
      var x = pos[3 * v], y = pos[3 * v + 1], z = pos[3 * v + 2];
      var cx = R[0][0] * x + R[0][1] * y + R[0][2] * z + t[0];
      var cy = R[1][0] * x + R[1][1] * y + R[1][2] * z + t[1];
      var cz = R[2][0] * x + R[2][1] * y + R[2][2] * z + t[2];
      if (!(cz > 0)) return null;
      var u = K[0][0] * cx / cz + K[0][1] * cy / cz + K[0][2], w = K[1][1] * cy / cz + K[1][2];
      return [(u + 0.5) * sx, (w + 0.5) * sy];  // canvas units: pixel (0, 0) covers [0, 1)
    }
    var edges = faceEdges(faces);
    ctx.beginPath();
    for (var e = 0; e < edges.length; e += 4) {
      var f1 = edges[e + 2], f2 = edges[e + 3];
      var outline = f2 < 0 ? front[f1] === 1 : front[f1] !== front[f2];
      if (!outline) continue;
      var p = pixel(edges[e]), r = pixel(edges[e + 1]);
      if (!p || !r) continue;
      ctx.moveTo(p[0], p[1]); ctx.lineTo(r[0], r[1]);
      outlineEdges++;
    }
    ctx.strokeStyle = "rgba(255, 0, 200, 0.9)";
    ctx.lineWidth = 1.5 * dpr;
    ctx.stroke();
  }

  function setVideo(i) {
    if (!video) return;
    var c = video.cameras[state.camera];
    var src = c.images[Math.min(i, c.images.length - 1)];
    if (videoImage.getAttribute("src") !== src) videoImage.src = src;
    drawOutline(i, c);
  }

  function showCamera(index) {
    state.camera = Math.max(0, Math.min(video.cameras.length - 1, Number(index) || 0));
    var c = video.cameras[state.camera];
    videoImage.width = c.shownWidth; videoImage.height = c.shownHeight;
    var scaled = c.shownWidth !== c.width || c.shownHeight !== c.height;
    document.getElementById("fourd-video-note").textContent = scaled
      ? "Images downscaled from " + c.width + "\u00d7" + c.height + " to " + c.shownWidth + "\u00d7" + c.shownHeight +
        " pixels to keep the page small (fourd view --video-size)."
      : "Images at their full size, " + c.width + "\u00d7" + c.height + " pixels.";
    setVideo(state.frame);
  }

  function resize() {
    var box = canvas.parentElement.getBoundingClientRect();
    var w = Math.max(1, Math.floor(box.width)), h = Math.max(1, Math.floor(box.height));
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    draw();
    setVideo(state.frame);
  }

  // ------------------------------------------------------------------ playback
  var span = T > 1 ? times[T - 1] - times[0] : 1;
  var step = T > 1 ? span / (T - 1) : 1;
  var fps = D.fps || 10;
  var last = null;
  function tick(now) {
    if (last === null) last = now;
    var dt = (now - last) / 1000; last = now;
    if (state.playing && T > 1) {
      // D.fps frames per second at speed 1, following the frame times
      state.clock += dt * state.speed * fps * step;
      var tt = times[0] + (state.clock % (span + step));
      var i = 0;
      while (i + 1 < T && times[i + 1] <= tt) i++;
      if (i !== state.frame) setFrame(i);
    }
    controls.update();
    draw();
    requestAnimationFrame(tick);
  }

  // ------------------------------------------------------------------ UI
  function bind(id, event, fn) { var el = document.getElementById(id); if (el) el.addEventListener(event, fn); return el; }
  var slider = document.getElementById("fourd-frame");
  slider.max = String(T - 1);
  bind("fourd-frame", "input", function (e) { state.playing = false; updatePlay(); setFrame(e.target.value); });
  function updatePlay() { document.getElementById("fourd-play").textContent = state.playing ? "Pause" : "Play"; }
  bind("fourd-play", "click", function () {
    state.playing = !state.playing;
    if (state.playing) state.clock = times[state.frame] - times[0];
    updatePlay();
  });
  bind("fourd-prev", "click", function () { state.playing = false; updatePlay(); setFrame(state.frame - 1); });
  bind("fourd-next", "click", function () { state.playing = false; updatePlay(); setFrame(state.frame + 1); });
  bind("fourd-speed", "change", function (e) { state.speed = Number(e.target.value); });
  bind("fourd-texture", "change", function (e) { state.texture = e.target.value; draw(); });
  bind("fourd-points", "change", function (e) { state.showPoints = e.target.checked; draw(); });
  bind("fourd-filled", "change", function (e) { state.showFilled = e.target.checked; draw(); });
  bind("fourd-errors", "change", function (e) {
    state.showErrors = e.target.checked;
    if (state.showErrors && state.showCarried) { state.showCarried = false; document.getElementById("fourd-carried").checked = false; }
    setFrame(state.frame);
  });
  bind("fourd-carried", "change", function (e) {
    // one colouring at a time; the checker would darken the colours and the points are the
    // reference they are compared against, so both follow the toggle
    state.showCarried = e.target.checked;
    if (state.showCarried && state.showErrors) { state.showErrors = false; document.getElementById("fourd-errors").checked = false; }
    state.texture = state.showCarried ? "none" : "checker";
    document.getElementById("fourd-texture").value = state.texture;
    if (points.length) { state.showPoints = state.showCarried; document.getElementById("fourd-points").checked = state.showPoints; }
    setFrame(state.frame);
  });
  bind("fourd-camera", "change", function (e) { showCamera(e.target.value); });
  bind("fourd-outline", "change", function (e) { state.showOutline = e.target.checked; setVideo(state.frame); });
  bind("fourd-glb", "change", function (e) { state.showGlb = e.target.checked; draw(); });
  if (!points.length) document.getElementById("fourd-points").disabled = true;
  if (!observed) document.getElementById("fourd-filled").disabled = true;
  if (!D.hasErrors) document.getElementById("fourd-errors").disabled = true;
  if (!carried) document.getElementById("fourd-carried").disabled = true;
  else document.getElementById("fourd-carried-note").hidden = false;
  if (video) {
    var select = document.getElementById("fourd-camera");
    video.cameras.forEach(function (c, k) {
      var option = document.createElement("option");
      option.value = String(k); option.textContent = c.name;
      select.appendChild(option);
    });
    document.getElementById("fourd-video").hidden = false;
    showCamera(0);
  }
  document.addEventListener("keydown", function (e) {
    if (e.target && e.target.tagName === "SELECT") return;
    if (e.key === " ") { e.preventDefault(); document.getElementById("fourd-play").click(); }
    else if (e.key === "ArrowRight") setFrame(state.frame + 1);
    else if (e.key === "ArrowLeft") setFrame(state.frame - 1);
  });

  function formatNumber(value) {
    return Number.isInteger(value) ? String(value) : Number(value).toPrecision(4);
  }

  (function metricsPanel() {
    var box = document.getElementById("fourd-metrics");
    var rows = [];
    function walk(prefix, value) {
      if (value !== null && typeof value === "object" && !Array.isArray(value)) {
        Object.keys(value).forEach(function (k) { walk(prefix ? prefix + "." + k : k, value[k]); });
      } else if (Array.isArray(value)) {
        // a per-frame curve: its range, not every value
        var numbers = value.filter(function (v) { return typeof v === "number" && isFinite(v); });
        var text = value.length + " values";
        if (numbers.length) {
          var lo = Math.min.apply(null, numbers), hi = Math.max.apply(null, numbers);
          text = lo === hi ? formatNumber(lo) + " (" + text + ")" : formatNumber(lo) + " .. " + formatNumber(hi);
        }
        rows.push([prefix, text]);
      } else {
        var shown = typeof value === "number" ? formatNumber(value)
          : value === null ? "-" : typeof value === "string" ? value : JSON.stringify(value);
        rows.push([prefix, shown]);
      }
    }
    walk("", D.metrics || {});
    if (!rows.length) { box.textContent = "no metrics (fourd view --truth TRUTH computes them)"; return; }
    var table = document.createElement("table");
    rows.forEach(function (r) {
      var tr = document.createElement("tr");
      var a = document.createElement("td"); a.className = "fourd-key";
      // a line may break after "." or "_" only
      r[0].replace(/([._])/g, "$1\n").split("\n").forEach(function (part, i) {
        if (i) a.appendChild(document.createElement("wbr"));
        a.appendChild(document.createTextNode(part));
      });
      var b = document.createElement("td"); b.className = "fourd-value"; b.textContent = r[1];
      tr.appendChild(a); tr.appendChild(b); table.appendChild(tr);
    });
    box.appendChild(table);
  })();

  (function errorLegend() {
    // what the error colours mean: the colour map from 0 to the scale, in input units
    if (!D.hasErrors) return;
    var scale = D.errorScale || 1;
    var stops = lut.map(function (c, i) {
      return "rgb(" + c.map(function (x) { return Math.round(255 * x); }).join(",") + ") " + (100 * i / (lut.length - 1)).toFixed(1) + "%";
    });
    document.getElementById("fourd-colorbar").style.background = "linear-gradient(to right, " + stops.join(", ") + ")";
    document.getElementById("fourd-colorbar-mid").textContent = formatNumber(scale / 2);
    document.getElementById("fourd-colorbar-hi").textContent = "\u2265 " + formatNumber(scale);
    var share = D.truthDiagonal ? " (" + (100 * scale / D.truthDiagonal).toPrecision(2) + "% of the truth's diagonal)" : "";
    document.getElementById("fourd-colorbar-text").textContent = D.errorLegend ||
      ("Distance from each vertex to the truth's surface, in input units: pale is on the truth, dark is far. " +
      "The scale ends at the 98th percentile over all vertices and frames, " + formatNumber(scale) + share +
      "; farther vertices take the darkest colour.");
    if (D.errorLabel) document.getElementById("fourd-errors").parentNode.lastChild.textContent = " " + D.errorLabel;
    document.getElementById("fourd-error-legend").hidden = false;
  })();
  document.getElementById("fourd-caption").textContent = D.caption || "";

  // ------------------------------------------------------------------ test hooks
  window.fourdSetFrame = setFrame;
  window.fourdSetOptions = function (o) { Object.assign(state, o || {}); setFrame(state.frame); return Object.assign({}, state); };
  window.fourdPixels = function (size) {
    size = size || 32;
    draw();
    var c = document.createElement("canvas"); c.width = size; c.height = size;
    var ctx = c.getContext("2d");
    ctx.drawImage(renderer.domElement, 0, 0, size, size);
    var px = ctx.getImageData(0, 0, size, size).data;
    var grey = [], ink = 0;
    for (var i = 0; i < px.length; i += 4) {
      var g = (px[i] + px[i + 1] + px[i + 2]) / 3;
      grey.push(Math.round(g));
      if (g < 245) ink++;
    }
    return { size: size, grey: grey, inkFraction: ink / (size * size), width: renderer.domElement.width, height: renderer.domElement.height };
  };
  window.fourdVideo = function () {
    if (!video) return null;
    var c = video.cameras[state.camera];
    return { camera: c.name, cameras: video.cameras.length, frame: state.frame, images: c.images.length,
             src: videoImage.getAttribute("src") === c.images[state.frame], complete: videoImage.complete,
             naturalWidth: videoImage.naturalWidth, naturalHeight: videoImage.naturalHeight,
             shownWidth: c.shownWidth, shownHeight: c.shownHeight, outlineEdges: outlineEdges,
             note: document.getElementById("fourd-video-note").textContent };
  };
  window.fourdGlbCheck = function (i) {
    if (!glb) return null;
    setFrame(i);
    glb.root.updateMatrixWorld(true);
    var out = { frame: i, meshes: [] };
    var v = new THREE.Vector3();
    glb.meshes.forEach(function (m) {
      var n = m.geometry.getAttribute("position").count;
      var box = new THREE.Box3();
      var sample = [];
      var stride = Math.max(1, Math.floor(n / 64));
      for (var k = 0; k < n; k++) {
        m.getVertexPosition(k, v);
        v.applyMatrix4(m.matrixWorld);
        box.expandByPoint(v);
        if (k % stride === 0) sample.push([k, v.x, v.y, v.z]);
      }
      out.meshes.push({ vertexCount: n, morphTargets: (m.geometry.morphAttributes.position || []).length,
                        influences: Array.from(m.morphTargetInfluences || []),
                        min: box.min.toArray(), max: box.max.toArray(), sample: sample });
    });
    return out;
  };

  function finish() {
    resize();
    setFrame(0);
    window.fourdInfo = { kind: D.kind, frameCount: T, vertexCount: N, hasErrors: !!D.hasErrors,
                         hasPoints: points.length > 0, hasObserved: !!observed,
                         hasCarried: !!carried, hasVideo: !!video,
                         glb: glb ? { clips: glb.clipNames, duration: glb.clip ? glb.clip.duration : 0,
                                      keyCount: glb.keyTimes ? glb.keyTimes.length : 0, meshes: glb.meshes.length } : null };
    var status = document.getElementById("fourd-status");
    if (status) status.textContent = (animated ? "animated mesh" : "mesh sequence") + ", " + T + " frames" + (glb ? ", .glb loaded" : "");
    window.fourdReady = true;
    requestAnimationFrame(tick);
  }

  window.addEventListener("resize", resize);
  setGeometry(0);
  function loadGlb(buffer) {
    var loader = new THREE.GLTFLoader();
    loader.parse(buffer, "", function (gltf) {
      var root = gltf.scene;
      var meshes = [];
      root.traverse(function (o) {
        if (o.isMesh) {
          meshes.push(o);
          var g = o.geometry, n = g.getAttribute("position").count;
          if (animated && n === N) {
            // same vertices in the same order: paint the first-frame texture on the glb too
            g.setAttribute("fourdTex", new THREE.BufferAttribute(texcoordFirst, 3));
            g.setAttribute("fourdColor", new THREE.BufferAttribute(new Float32Array(n * 3).fill(1), 3));
            g.setAttribute("fourdFilled", new THREE.BufferAttribute(new Float32Array(n), 1));
            o.material = material;
          } else {
            o.material = new THREE.MeshLambertMaterial({ color: 0xb8ad9c, side: THREE.DoubleSide });
          }
          if (!g.getAttribute("normal")) g.computeVertexNormals();
        }
      });
      var mixer = new THREE.AnimationMixer(root);
      var clip = gltf.animations[0] || null;
      var keyTimes = null, action = null;
      if (clip) {
        action = mixer.clipAction(clip);
        action.setLoop(THREE.LoopOnce, 1);
        action.clampWhenFinished = true;
        action.play();
        keyTimes = clip.tracks.length ? Array.from(clip.tracks[0].times) : null;
      }
      root.visible = false;
      scene.add(root);
      glb = { root: root, mixer: mixer, clip: clip, action: action, keyTimes: keyTimes, meshes: meshes,
              clipNames: gltf.animations.map(function (a) { return a.name; }) };
      document.getElementById("fourd-glb").disabled = false;
      finish();
    }, function (err) { fail("could not read the .glb: " + (err && err.message ? err.message : err)); finish(); });
  }
  if (D.glb) {
    loadGlb(decode(D.glb, Uint8Array).buffer);
  } else if (D.glbUrl && /^https?:$/.test(window.location.protocol)) {
    // too big to inline: fetch it from beside the page (HTTP only; file:// cannot fetch)
    fetch(D.glbUrl).then(function (r) {
      if (!r.ok) throw new Error(D.glbUrl + ": HTTP " + r.status);
      return r.arrayBuffer();
    }).then(loadGlb).catch(function (err) { fail("could not load " + D.glbUrl + ": " + err.message); finish(); });
  } else {
    if (D.glbUrl) {
      var hint = "The .glb is too big to inline and a page opened from a file cannot load it: serve this folder " +
        "(python -m http.server -d FOLDER) and open http://localhost:8000/ to play " + D.glbUrl + ".";
      document.getElementById("fourd-glb").title = hint;
      var note = document.getElementById("fourd-glb-note");
      if (note) { note.textContent = hint; note.hidden = false; }
    }
    finish();
  }
})();
