// rangekit report: a small self-contained WebGL mesh viewer (no library, no network).
// Reads the JSON in <script type="application/json" id="rk-mesh">: {pos: base64 float32 (V*3), idx: base64
// uint32 (T*3), colours: {name: base64 uint8 RGB (V*3)}, centre: [x,y,z], radius: r, up: [x,y,z]} and draws it
// into <canvas id="rk-view">: headlight Lambert shading, orbit by mouse drag, zoom by the wheel, the colour
// scheme chosen in <select id="rk-colour">.
(function () {
  "use strict";
  var canvas = document.getElementById("rk-view");
  var spec = JSON.parse(document.getElementById("rk-mesh").textContent);
  var gl = canvas.getContext("webgl", {preserveDrawingBuffer: true, antialias: true});
  if (!gl || !gl.getExtension("OES_element_index_uint")) {
    canvas.insertAdjacentHTML("afterend", "<p>This browser has no WebGL: the 3D view is not shown.</p>");
    return;
  }
  function bytes(b64) {
    var s = atob(b64), out = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out.buffer;
  }
  var pos = new Float32Array(bytes(spec.pos)), idx = new Uint32Array(bytes(spec.idx));
  // Area-weighted vertex normals.
  var nrm = new Float32Array(pos.length);
  for (var t = 0; t < idx.length; t += 3) {
    var a = 3 * idx[t], b = 3 * idx[t + 1], c = 3 * idx[t + 2];
    var ux = pos[b] - pos[a], uy = pos[b + 1] - pos[a + 1], uz = pos[b + 2] - pos[a + 2];
    var vx = pos[c] - pos[a], vy = pos[c + 1] - pos[a + 1], vz = pos[c + 2] - pos[a + 2];
    var nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    for (var k = 0; k < 3; k++) {
      var p = 3 * idx[t + k];
      nrm[p] += nx; nrm[p + 1] += ny; nrm[p + 2] += nz;
    }
  }
  function shader(type, src) {
    var s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    return s;
  }
  var prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER,
    "attribute vec3 p; attribute vec3 n; attribute vec3 c; uniform mat4 mv; uniform mat4 pr;" +
    "varying vec3 vn; varying vec3 vc;" +
    "void main() { vn = (mv * vec4(n, 0.0)).xyz; vc = c; gl_Position = pr * mv * vec4(p, 1.0); }"));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER,
    "precision mediump float; varying vec3 vn; varying vec3 vc;" +
    "void main() { float l = abs(normalize(vn).z); gl_FragColor = vec4(vc * (0.3 + 0.7 * l), 1.0); }"));
  gl.linkProgram(prog);
  gl.useProgram(prog);
  function attribute(name, data, type, normalised) {
    var buf = gl.createBuffer(), loc = gl.getAttribLocation(prog, name);
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, type, normalised, 0, 0);
    return buf;
  }
  attribute("p", pos, gl.FLOAT, false);
  attribute("n", nrm, gl.FLOAT, false);
  var colourBuf = attribute("c", new Uint8Array(pos.length), gl.UNSIGNED_BYTE, true);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
  gl.enable(gl.DEPTH_TEST);

  function norm(v) { var l = Math.hypot(v[0], v[1], v[2]) || 1; return [v[0] / l, v[1] / l, v[2] / l]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  // The orbit turns about "up" (yaw) and tilts towards it (pitch), as the report's pictures: e1 the world x (y if
  // up is near x) made normal to up, e2 = up x e1; it starts where the "front" picture is taken (0, 25 deg).
  var up = norm(spec.up), ax = Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0], d0 = dot(ax, up);
  var ex = norm([ax[0] - d0 * up[0], ax[1] - d0 * up[1], ax[2] - d0 * up[2]]), ey = cross(up, ex);
  var yaw = 0.0, pitch = 25 * Math.PI / 180, dist = 3.0 * spec.radius, C = spec.centre;

  function draw() {
    var w = canvas.width, h = canvas.height;
    var cp = Math.cos(pitch), sp = Math.sin(pitch), cy = Math.cos(yaw), sy = Math.sin(yaw);
    var dir = [0, 1, 2].map(function (i) { return cp * (cy * ex[i] + sy * ey[i]) + sp * up[i]; });   // centre to eye
    var eye = [0, 1, 2].map(function (i) { return C[i] + dist * dir[i]; });
    var z = dir, x = norm(cross(up, z));
    if (!isFinite(x[0]) || Math.hypot(x[0], x[1], x[2]) < 1e-6) x = ex;
    var y = cross(z, x);
    var mv = new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
                               -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
    var f = 1 / Math.tan(0.35), near = Math.max(dist - 2 * spec.radius, dist * 0.01), far = dist + 2 * spec.radius;
    var pr = new Float32Array([f * h / w, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1,
                               0, 0, 2 * far * near / (near - far), 0]);
    gl.viewport(0, 0, w, h);
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.uniformMatrix4fv(gl.getUniformLocation(prog, "mv"), false, mv);
    gl.uniformMatrix4fv(gl.getUniformLocation(prog, "pr"), false, pr);
    gl.drawElements(gl.TRIANGLES, idx.length, gl.UNSIGNED_INT, 0);
  }
  function setColours(name) {
    gl.bindBuffer(gl.ARRAY_BUFFER, colourBuf);
    gl.bufferData(gl.ARRAY_BUFFER, new Uint8Array(bytes(spec.colours[name])), gl.STATIC_DRAW);
    document.querySelectorAll(".rk-legend").forEach(function (el) {
      el.style.display = el.getAttribute("data-colour") === name ? "" : "none";
    });
    draw();
  }
  var select = document.getElementById("rk-colour");
  select.addEventListener("change", function () { setColours(select.value); });
  var last = null;
  canvas.addEventListener("pointerdown", function (e) { last = [e.clientX, e.clientY]; });
  window.addEventListener("pointerup", function () { last = null; });
  window.addEventListener("pointermove", function (e) {
    if (!last) return;
    yaw -= 0.01 * (e.clientX - last[0]);
    pitch = Math.max(-1.55, Math.min(1.55, pitch + 0.01 * (e.clientY - last[1])));
    last = [e.clientX, e.clientY];
    draw();
  });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    dist = Math.max(0.5 * spec.radius, Math.min(20 * spec.radius, dist * Math.exp(0.001 * e.deltaY)));
    draw();
  }, {passive: false});
  setColours(select.value);
})();
