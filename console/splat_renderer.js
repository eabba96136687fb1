// A WebGL2 Gaussian-splat renderer for the console: each Gaussian is a screen-space quad
// (the EWA projection of its 3D covariance through a pinhole camera with OpenCV axes, as the
// engine renders), sorted back to front on the CPU when the camera moves, and blended with
// premultiplied alpha. Per-Gaussian object ids let a selection be lit and the rest dimmed.
//
// Hand-written rather than a library renderer: the console needs per-object highlighting
// from labels.npy, the engine's camera model, and frame-exact training views for the mask
// overlay, and it must load from the binary without a bundler.

const TEXELS_PER_SPLAT = 4;
const TEXTURE_WIDTH = 4096;
export const MAX_SELECTED = 16;

const VERTEX_SHADER = `#version 300 es
precision highp float;
precision highp int;
uniform highp sampler2D u_data;
uniform mat4 u_view;
uniform vec4 u_intrinsics; // fx, fy, cx, cy in pixels
uniform vec2 u_viewport;
uniform float u_selected[${MAX_SELECTED}];
uniform int u_selectedCount;
layout(location = 0) in vec2 a_corner;
layout(location = 1) in uint a_index;
out vec4 v_color;
out vec2 v_offset;

vec4 texel(uint index, int k) {
  int flat_index = int(index) * ${TEXELS_PER_SPLAT} + k;
  return texelFetch(u_data, ivec2(flat_index % ${TEXTURE_WIDTH}, flat_index / ${TEXTURE_WIDTH}), 0);
}

void main() {
  vec4 t0 = texel(a_index, 0); // centre, opacity
  vec4 t1 = texel(a_index, 1); // xx xy xz yy
  vec4 t2 = texel(a_index, 2); // yz zz
  vec4 t3 = texel(a_index, 3); // colour, object id
  vec3 p = (u_view * vec4(t0.xyz, 1.0)).xyz;
  gl_Position = vec4(0.0, 0.0, 2.0, 1.0);
  if (p.z < 0.02) return;
  mat3 sigma = mat3(t1.x, t1.y, t1.z, t1.y, t1.w, t2.x, t1.z, t2.x, t2.y);
  mat3 w = mat3(u_view); // world to camera rotation
  float fx = u_intrinsics.x, fy = u_intrinsics.y;
  // Column-major: the Jacobian of the pinhole projection, rows (fx/z, 0, -fx x/z^2), (0, fy/z, -fy y/z^2).
  mat3 jacobian = mat3(fx / p.z, 0.0, 0.0, 0.0, fy / p.z, 0.0,
                       -fx * p.x / (p.z * p.z), -fy * p.y / (p.z * p.z), 0.0);
  mat3 projected = jacobian * w * sigma * transpose(w) * transpose(jacobian);
  float a = projected[0][0] + 0.3, b = projected[0][1], d = projected[1][1] + 0.3;
  float mid = 0.5 * (a + d);
  float radius = length(vec2(0.5 * (a - d), b));
  float major = mid + radius, minor = max(mid - radius, 0.0);
  if (minor <= 0.0) return;
  vec2 direction = abs(b) > 1e-9 ? normalize(vec2(b, major - a)) : (a >= d ? vec2(1.0, 0.0) : vec2(0.0, 1.0));
  vec2 axis1 = 3.0 * sqrt(major) * direction;
  vec2 axis2 = 3.0 * sqrt(minor) * vec2(-direction.y, direction.x);
  if (length(axis1) > 4096.0) return;
  vec2 center = vec2(fx * p.x / p.z + u_intrinsics.z, fy * p.y / p.z + u_intrinsics.w);
  vec2 pixel = center + a_corner.x * axis1 + a_corner.y * axis2;
  gl_Position = vec4(pixel.x / u_viewport.x * 2.0 - 1.0, 1.0 - pixel.y / u_viewport.y * 2.0, 0.0, 1.0);
  v_offset = a_corner;

  vec3 color = t3.rgb;
  float alpha = t0.w;
  if (u_selectedCount > 0) {
    bool selected = false;
    for (int i = 0; i < ${MAX_SELECTED}; i++) {
      if (i < u_selectedCount && u_selected[i] == t3.a) selected = true;
    }
    if (selected) {
      // Lit: its own colours, a little brighter and warmer, so the object stays recognisable.
      color = min(mix(color, vec3(1.0, 0.85, 0.2), 0.12) * 1.1, vec3(1.0));
    } else {
      color = vec3(dot(color, vec3(0.3, 0.59, 0.11))) * 0.35;
      alpha *= 0.15;
    }
  }
  v_color = vec4(color, alpha);
}`;

const FRAGMENT_SHADER = `#version 300 es
precision highp float;
in vec4 v_color;
in vec2 v_offset;
out vec4 fragment;
void main() {
  float r2 = dot(v_offset, v_offset);
  if (r2 > 1.0) discard;
  // The quad spans 3 sigma, so sigma-space distance squared is 9 r2.
  float alpha = min(0.99, v_color.a * exp(-4.5 * r2));
  if (alpha < 1.0 / 255.0) discard;
  fragment = vec4(v_color.rgb * alpha, alpha);
}`;

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) {
    throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
  }
  return shader;
}

export class SplatRenderer {
  constructor(canvas) {
    const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
    if (!gl) throw new Error("this browser has no WebGL2, which the 3D view needs");
    this.gl = gl;
    this.canvas = canvas;
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) {
      throw new Error(`shader program: ${gl.getProgramInfoLog(program)}`);
    }
    this.program = program;
    this.uniforms = Object.fromEntries(
      ["u_data", "u_view", "u_intrinsics", "u_viewport", "u_selected", "u_selectedCount"]
        .map((name) => [name, gl.getUniformLocation(program, name)]),
    );
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    const corners = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, corners);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
    this.indexBuffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, this.indexBuffer);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribIPointer(1, 1, gl.UNSIGNED_INT, 0, 0);
    gl.vertexAttribDivisor(1, 1);
    gl.bindVertexArray(null);
    this.texture = gl.createTexture();
    this.count = 0;
    this.selected = [];
  }

  // Uploads Gaussians (from parseSplatPly) with each one's object id (a float, exact below 2^24;
  // -1 for none).
  setSplats(splats, objectIds) {
    const n = splats.count;
    this.splats = splats;
    this.data = new Float32Array(TEXTURE_WIDTH * Math.max(1, Math.ceil((n * TEXELS_PER_SPLAT) / TEXTURE_WIDTH)) * 4);
    for (let i = 0; i < n; i++) {
      const base = i * TEXELS_PER_SPLAT * 4;
      this.data.set(splats.centers.subarray(i * 3, i * 3 + 3), base);
      this.data[base + 3] = splats.colors[i * 4 + 3];
      this.data.set(splats.covariances.subarray(i * 6, i * 6 + 6), base + 4);
      this.data.set(splats.colors.subarray(i * 4, i * 4 + 3), base + 12);
    }
    this.count = n;
    this.setObjectIds(objectIds);
    this.order = new Uint32Array(n);
    this.depthKeys = new Uint16Array(n);
    this.sortedFor = null;
  }

  setObjectIds(objectIds) {
    for (let i = 0; i < this.count; i++) {
      this.data[i * TEXELS_PER_SPLAT * 4 + 15] = objectIds ? objectIds[i] : -1;
    }
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, TEXTURE_WIDTH, this.data.length / 4 / TEXTURE_WIDTH,
      0, gl.RGBA, gl.FLOAT, this.data);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  }

  // Forgets the Gaussians and clears the canvas (another scene is being opened).
  clear() {
    this.count = 0;
    const gl = this.gl;
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
  }

  select(objectIds) {
    this.selected = objectIds.slice(0, MAX_SELECTED);
  }

  // Back to front by camera depth: a 16-bit counting sort, linear in the Gaussian count.
  sort(view) {
    const n = this.count;
    const centers = this.splats.centers;
    const depths = new Float32Array(n);
    let near = Infinity;
    let far = -Infinity;
    for (let i = 0; i < n; i++) {
      const z = view[2] * centers[i * 3] + view[6] * centers[i * 3 + 1] + view[10] * centers[i * 3 + 2] + view[14];
      depths[i] = z;
      if (z < near) near = z;
      if (z > far) far = z;
    }
    const scale = 65535 / Math.max(1e-9, far - near);
    const counts = new Uint32Array(65536);
    for (let i = 0; i < n; i++) {
      const key = 65535 - Math.floor((depths[i] - near) * scale);
      this.depthKeys[i] = key;
      counts[key]++;
    }
    for (let k = 1; k < 65536; k++) counts[k] += counts[k - 1];
    for (let i = n - 1; i >= 0; i--) this.order[--counts[this.depthKeys[i]]] = i;
    const gl = this.gl;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.indexBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, this.order, gl.DYNAMIC_DRAW);
  }

  // camera: { view (column-major 4x4 world to camera), fx, fy, cx, cy } in canvas pixels.
  draw(camera) {
    const gl = this.gl;
    gl.viewport(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    if (!this.count) return;
    const key = camera.view.join(",");
    if (this.sortedFor !== key) {
      this.sort(camera.view);
      this.sortedFor = key;
    }
    gl.useProgram(this.program);
    gl.disable(gl.DEPTH_TEST);
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.uniform1i(this.uniforms.u_data, 0);
    gl.uniformMatrix4fv(this.uniforms.u_view, false, camera.view);
    gl.uniform4f(this.uniforms.u_intrinsics, camera.fx, camera.fy, camera.cx, camera.cy);
    gl.uniform2f(this.uniforms.u_viewport, this.canvas.width, this.canvas.height);
    const selected = new Float32Array(MAX_SELECTED).fill(-2);
    selected.set(this.selected);
    gl.uniform1fv(this.uniforms.u_selected, selected);
    gl.uniform1i(this.uniforms.u_selectedCount, this.selected.length);
    gl.bindVertexArray(this.vao);
    gl.drawArraysInstanced(gl.TRIANGLE_STRIP, 0, 4, this.count);
    gl.bindVertexArray(null);
  }
}
